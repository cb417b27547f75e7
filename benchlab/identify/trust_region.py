"""Bounded nonlinear least squares: scipy's trust-region reflective method, each step decomposed from the Jacobian's
triangular factor.

scipy's `least_squares(method="trf")` takes an SVD of the scaled Jacobian stacked on the bounds' diagonal,
[J d; D] ((m + n) × n for m residuals, n parameters), at every iteration. Everything its step uses from that SVD
(the singular values, the right singular vectors, Uᵀ f, and the norms and products of J_h p in choosing the step)
is the same for [R d; D] and Qᵀ f, with J = QR: so the QR of J is taken once per Jacobian and the SVD of a 2n × n
matrix per iteration (a 2 h identification: m = 42,000, n = 15). The method, its scaling (x_scale="jac"), radius
updates and stopping rules are scipy's `trf_bounds` (scipy.optimize._lsq.trf, BSD licence) with the exact solver
and the linear loss, the Jacobian its 2-point finite differences with the same steps: the same iterates up to
rounding.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.linalg import norm
from scipy.linalg import qr_multiply, svd
from scipy.optimize import OptimizeResult, least_squares

try:  # scipy's own trf building blocks: private, so pinned by the lock; a release that moves them gets _public
    from scipy.optimize._lsq.common import (CL_scaling_vector, check_termination, compute_grad,
                                            make_strictly_feasible, solve_lsq_trust_region, update_tr_radius)
    from scipy.optimize._lsq.trf import select_step
    from scipy.optimize._numdiff import approx_derivative
except ImportError:  # pragma: no cover - depends on the installed scipy; tests/test_trust_region.py forces it
    select_step = None


def least_squares_trf(fun: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, bounds: tuple[np.ndarray, np.ndarray],
                      workers: Callable, max_nfev: int | None = None, ftol: float = 1e-8, xtol: float = 1e-8,
                      gtol: float = 1e-8, stop: Callable[[np.ndarray], bool] | None = None,
                      stall: tuple[int, float] | None = None) -> OptimizeResult:
    """`scipy.optimize.least_squares(fun, x0, bounds=bounds, method="trf", x_scale="jac", workers=workers, ...)`
    with its 2-point Jacobian; `stop(x)` after each iteration, True ends the fit (status -2, as a callback's
    StopIteration); `stall` = (k, share): the fit also ends (status 2, ftol's) once its last k steps together
    lowered the cost by less than that share, as a fit crawling along a valley does. Returns x, cost, fun, jac,
    nfev, njev and status as least_squares does."""
    if select_step is None:
        return _public(fun, x0, bounds, workers, max_nfev, ftol, xtol, gtol, stop, stall)
    lb, ub = bounds
    x0 = make_strictly_feasible(np.asarray(x0, dtype=float), lb, ub)

    def jacobian(x: np.ndarray, f: np.ndarray) -> np.ndarray:
        return np.atleast_2d(approx_derivative(fun, x, method="2-point", f0=f, bounds=bounds, workers=workers))

    x, f = x0.copy(), np.atleast_1d(fun(x0))
    if not np.all(np.isfinite(f)):
        raise ValueError("Residuals are not finite in the initial point.")
    J = jacobian(x, f)
    nfev = njev = 1
    m, n = J.shape
    cost = 0.5 * np.dot(f, f)
    g = compute_grad(J, f)
    scale, scale_inv = _jac_scale(J)
    work = np.empty(J.shape, order="F")  # the QR's working copy, one per fit (a 24 h run's J is 62 MB)
    R, qf = _triangular(J, f, work)
    v, dv = CL_scaling_vector(x, g, lb, ub)
    v[dv != 0] *= scale_inv[dv != 0]
    Delta = norm(x0 * scale_inv / v ** 0.5) or 1.0
    max_nfev = x0.size * 100 if max_nfev is None else max_nfev
    alpha = 0.0  # the Levenberg-Marquardt parameter
    status = None
    costs = [cost]  # the cost after each accepted step, for `stall`
    while True:
        v, dv = CL_scaling_vector(x, g, lb, ub)
        g_norm = norm(g * v, ord=np.inf)
        if g_norm < gtol:
            status = 1
        if status is not None or nfev == max_nfev:
            break
        v[dv != 0] *= scale_inv[dv != 0]
        d = v ** 0.5 * scale
        diag_h = g * dv * scale
        g_h = d * g
        R_h = R * d  # J_h = J d = Q (R d): the step reads J_h only through R_h's norms and products
        U, s, V = svd(np.vstack((R_h, np.diag(diag_h ** 0.5))), full_matrices=False)
        V = V.T
        uf = U[: len(qf)].T.dot(qf)
        theta = max(0.995, 1 - g_norm)
        actual_reduction = -1.0
        while actual_reduction <= 0 and nfev < max_nfev:
            p_h, alpha, _ = solve_lsq_trust_region(n, m, uf, s, V, Delta, initial_alpha=alpha)
            step, step_h, predicted_reduction = select_step(x, R_h, diag_h, g_h, d * p_h, p_h, d, Delta, lb, ub,
                                                            theta)
            x_new = make_strictly_feasible(x + step, lb, ub, rstep=0)
            f_new = np.atleast_1d(fun(x_new))
            nfev += 1
            step_h_norm = norm(step_h)
            if not np.all(np.isfinite(f_new)):
                Delta = 0.25 * step_h_norm
                continue
            cost_new = 0.5 * np.dot(f_new, f_new)
            actual_reduction = cost - cost_new
            Delta_new, ratio = update_tr_radius(Delta, actual_reduction, predicted_reduction, step_h_norm,
                                                step_h_norm > 0.95 * Delta)
            status = check_termination(actual_reduction, cost, norm(step), norm(x), ratio, ftol, xtol)
            if status is not None:
                break
            alpha *= Delta / Delta_new
            Delta = Delta_new
        if actual_reduction > 0:
            x, f, cost = x_new, f_new, cost_new
            J = jacobian(x, f)
            njev += 1
            g = compute_grad(J, f)
            scale, scale_inv = _jac_scale(J, scale_inv)
            R, qf = _triangular(J, f, work)
            costs.append(cost)
            if status is None and stalled(costs, stall):
                status = 2
        if stop is not None and status is None and stop(x):
            status = -2
            break
    return OptimizeResult(x=x, cost=cost, fun=f, jac=J, nfev=nfev, njev=njev, status=0 if status is None else status)


def stalled(costs: list[float], stall: tuple[int, float] | None) -> bool:
    """Whether the last k accepted steps (`stall` = (k, share)) lowered the cost by less than share of it."""
    if stall is None or len(costs) <= stall[0]:
        return False
    steps, share = stall
    return costs[-1 - steps] - costs[-1] < share * costs[-1]


def _triangular(J: np.ndarray, f: np.ndarray, work: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R and Qᵀf of J = QR (economic: R is min(m, n) × n), factorised in `work` (Fortran order, J's shape)."""
    np.copyto(work, J)
    qf, R = qr_multiply(work, f, mode="right", overwrite_a=True)
    return R, qf


def _jac_scale(J: np.ndarray, scale_inv_old: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """scipy's compute_jac_scale (x_scale="jac": the columns' norms, never shrinking), a column at a time instead of
    through a temporary J² (the same sums: each column is contiguous in the Jacobian's layout)."""
    scale_inv = np.array([np.sum(J[:, j] ** 2) for j in range(J.shape[1])]) ** 0.5
    if scale_inv_old is None:
        scale_inv[scale_inv == 0] = 1
    else:
        scale_inv = np.maximum(scale_inv, scale_inv_old)
    return 1 / scale_inv, scale_inv


def _public(fun: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, bounds: tuple[np.ndarray, np.ndarray],
            workers: Callable, max_nfev: int | None, ftol: float, xtol: float, gtol: float,
            stop: Callable[[np.ndarray], bool] | None, stall: tuple[int, float] | None) -> OptimizeResult:
    """The same fit by scipy's public `least_squares` (an SVD of the whole Jacobian per iteration): the answer where
    an installed scipy keeps the private helpers elsewhere, at scipy's cost."""
    costs: list[float] = []
    ended_stalled = [False]

    def callback(intermediate_result: OptimizeResult) -> None:
        costs.append(float(intermediate_result.cost))
        if stalled(costs, stall):
            ended_stalled[0] = True
            raise StopIteration
        if stop is not None and stop(intermediate_result.x):
            raise StopIteration  # least_squares ends with status -2

    result = least_squares(fun, x0, bounds=bounds, method="trf", x_scale="jac", max_nfev=max_nfev, xtol=xtol,
                           ftol=ftol, gtol=gtol, workers=workers, callback=callback)
    if ended_stalled[0]:
        result.status = 2
    return result
