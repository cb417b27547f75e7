"""benchlab.identify.trust_region: scipy's trust-region reflective least squares with QR-reduced steps."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from benchlab.identify import trust_region
from benchlab.identify.trust_region import least_squares_trf

T = np.linspace(0.0, 4.0, 400)


def _decay(x: np.ndarray) -> np.ndarray:
    """Two exponentials against noisy data: a small nonlinear problem with correlated parameters."""
    rng = np.random.default_rng(1)
    data = 3.0 * np.exp(-1.3 * T) + 0.7 * np.exp(-0.2 * T) + 0.01 * rng.standard_normal(T.size)
    return x[0] * np.exp(-x[1] * T) + x[2] * np.exp(-x[3] * T) - data


def _columns(fun):
    return lambda _f, points: [fun(x) for x in points]


@pytest.mark.parametrize("upper", [np.full(4, 10.0), np.array([10.0, 10.0, 0.5, 10.0])], ids=["free", "bound active"])
def test_reaches_scipys_minimum(upper):
    lower, x0 = np.zeros(4), np.array([1.0, 2.0, 0.3, 0.05])
    ours = least_squares_trf(_decay, x0, (lower, upper), _columns(_decay), xtol=1e-12, ftol=1e-12, gtol=1e-12)
    theirs = least_squares(_decay, x0, bounds=(lower, upper), method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12,
                           gtol=1e-12)
    assert ours.status > 0 and ours.cost == pytest.approx(theirs.cost, rel=1e-9)
    np.testing.assert_allclose(ours.x, theirs.x, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(ours.jac, theirs.jac, rtol=1e-5, atol=1e-8)
    assert abs(ours.nfev - theirs.nfev) <= 2


def test_stop_ends_the_fit_where_it_says():
    lower, upper, x0 = np.zeros(4), np.full(4, 10.0), np.array([1.0, 2.0, 0.3, 0.05])
    seen = []
    result = least_squares_trf(_decay, x0, (lower, upper), _columns(_decay),
                               stop=lambda x: seen.append(x.copy()) or len(seen) == 3)
    assert result.status == -2 and len(seen) == 3 and np.array_equal(result.x, seen[-1])
    np.testing.assert_array_equal(result.fun, _decay(result.x))


def test_a_scipy_without_the_private_helpers_gets_the_public_solver(monkeypatch):
    """Where a scipy release moves trf's private helpers, the fit is scipy's own least_squares: the same minimum,
    and `stop` still ends it."""
    lower, upper, x0 = np.zeros(4), np.full(4, 10.0), np.array([1.0, 2.0, 0.3, 0.05])
    fast = least_squares_trf(_decay, x0, (lower, upper), _columns(_decay), xtol=1e-12, ftol=1e-12, gtol=1e-12)
    monkeypatch.setattr(trust_region, "select_step", None)
    public = least_squares_trf(_decay, x0, (lower, upper), _columns(_decay), xtol=1e-12, ftol=1e-12, gtol=1e-12)
    assert public.status > 0 and public.cost == pytest.approx(fast.cost, rel=1e-9)
    np.testing.assert_allclose(public.x, fast.x, rtol=1e-6, atol=1e-9)
    seen = []
    stopped = least_squares_trf(_decay, x0, (lower, upper), _columns(_decay),
                                stop=lambda x: seen.append(x.copy()) or len(seen) == 3)
    assert stopped.status == -2 and len(seen) == 3
