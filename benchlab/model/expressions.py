"""Expressions of model files (`resistance`, `heat`) compiled once into vectorised numpy functions.

Python's `ast` only parses the text; nothing is ever evaluated by Python. The tree is checked against a
whitelist (numbers, names, `+ - * / **`, unary minus, one comparison `< <= > >= ==`, and calls of
`exp log sqrt abs minimum maximum where hysteresis`) and then turned into nested closures over numpy functions.
`hysteresis(x, off, on)` is a switch (a thermostat, a fan) whose state is carried from sample to sample
(benchlab.network.switching): the one function whose value is not pointwise (`Expression.sequential`).
A `heat` expression may name node temperatures where it is affine in them (a copper loss rising with
winding temperature): `affine_parts` splits it into a temperature-free part and one coefficient per node,
which the solver puts into the state matrix, so the zero-order hold stays exact.
"""

from __future__ import annotations

import ast
import operator
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

MAX_LENGTH = 2000  # characters: a model law, not a program
MAX_DEPTH = 100  # nesting of the parsed tree (a sum of n terms is n deep)

#: Function name -> (numpy function, number of arguments).
FUNCTIONS: dict[str, tuple[Callable, int]] = {
    "exp": (np.exp, 1), "log": (np.log, 1), "sqrt": (np.sqrt, 1), "abs": (np.abs, 1),
    "minimum": (np.minimum, 2), "maximum": (np.maximum, 2), "where": (np.where, 3),
    "hysteresis": (lambda x, off, on: _hysteresis(x, off, on), 3),
}
SEQUENTIAL = frozenset({"hysteresis"})  # functions whose value at a sample depends on the samples before it


def _hysteresis(x, off, on):
    """benchlab.network.switching.hysteresis, loaded on first use (it compiles with numba)."""
    from benchlab.network.switching import hysteresis

    return hysteresis(x, off, on)
_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.Pow: operator.pow}
_COMPARE = {ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
            ast.Eq: operator.eq}
_UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos}
ALLOWED = ("numbers, names, + - * / **, parentheses, one comparison < <= > >= ==, and "
           "exp log sqrt abs minimum maximum where(cond, a, b) hysteresis(x, off, on)")

#: A compiled expression: (parameters, channels, node temperatures) -> scalar or one value per sample.
Values = Mapping[str, "float | np.ndarray"]
Compiled = Callable[[Values, Values, Values], "float | np.ndarray"]


class ExpressionError(ValueError):
    """An expression outside the whitelist; the message says what was expected (the caller adds file and entry)."""


@dataclass(frozen=True)
class Expression:
    """A checked expression: its text, its parsed tree and the names it reads."""

    text: str
    tree: ast.expr = field(compare=False)  # equal texts parse to equal trees
    names: frozenset[str] = frozenset()

    @property
    def sequential(self) -> bool:
        """Whether its value at a sample depends on the samples before it (a `hysteresis` switch carries a state)."""
        return any(isinstance(n, ast.Call) and n.func.id in SEQUENTIAL for n in ast.walk(self.tree))


def parse(text: object) -> Expression:
    """Parse and check `text`; ExpressionError says what is wrong. Never evaluates anything."""
    if isinstance(text, bool) or not isinstance(text, (str, int, float)):
        raise ExpressionError(f"an expression (a string or a number), got {type(text).__name__}")
    source = text if isinstance(text, str) else repr(float(text))
    if len(source) > MAX_LENGTH:
        raise ExpressionError(f"an expression of at most {MAX_LENGTH} characters")
    return _parsed(source)


@lru_cache(maxsize=4096)
def _parsed(source: str) -> Expression:
    """`parse` of a string of at most MAX_LENGTH characters, kept: a diagnosis reads the model's laws again for each
    of the hundreds of candidates it builds (the tree is never changed after, so one may serve them all)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SyntaxWarning)  # "1x": the SyntaxError below says it, once
            tree = ast.parse(source.strip(), mode="eval").body
    except SyntaxError as exc:
        raise ExpressionError(f"an expression of {ALLOWED} (syntax error: {exc.msg})") from None
    except (ValueError, RecursionError, MemoryError):  # NUL bytes, absurd nesting
        raise ExpressionError(f"an expression of {ALLOWED}") from None
    names: set[str] = set()
    _check(tree, names, 0)
    return Expression(source, tree, frozenset(names))


def _check(node: ast.AST, names: set[str], depth: int) -> None:
    """Raise ExpressionError for any node outside the whitelist; collect the names read."""
    if depth > MAX_DEPTH:
        raise ExpressionError(f"an expression nested at most {MAX_DEPTH} deep")
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ExpressionError(f"a number, got {node.value!r}")
        return
    if isinstance(node, ast.Name):
        if node.id.startswith("__"):
            raise ExpressionError(f"a parameter, channel or node name, got {node.id!r}")
        names.add(node.id)
        return
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        _check(node.left, names, depth + 1)
        _check(node.right, names, depth + 1)
        return
    if isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
        _check(node.operand, names, depth + 1)
        return
    if isinstance(node, ast.Compare) and len(node.ops) == 1 and type(node.ops[0]) in _COMPARE:
        _check(node.left, names, depth + 1)
        _check(node.comparators[0], names, depth + 1)
        return
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            shown = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)[:40]
            raise ExpressionError(f"a call of one of {', '.join(FUNCTIONS)}, got {shown!r}")
        arity = FUNCTIONS[node.func.id][1]
        if node.keywords or len(node.args) != arity or any(isinstance(a, ast.Starred) for a in node.args):
            raise ExpressionError(f"{node.func.id} with {arity} positional argument{'s' * (arity > 1)}")
        for arg in node.args:
            _check(arg, names, depth + 1)
        return
    raise ExpressionError(f"an expression of {ALLOWED}, got {type(node).__name__} "
                          f"{ast.unparse(node)[:40]!r}" if isinstance(node, ast.expr) else
                          f"an expression of {ALLOWED}")


def _leaf(name: str, kind: str) -> Compiled:
    """A name's value; scalars as numpy floats, so that 1/0 is inf and (-1)**0.5 NaN as for arrays, never an
    exception or a complex number."""
    if kind == "parameter":
        return lambda p, c, t: np.float64(p[name])
    if kind == "channel":
        return lambda p, c, t: c[name]
    return lambda p, c, t: t[name]


def _constant(value: float) -> Compiled:
    value = np.float64(value)
    return lambda p, c, t: value


def compile_expression(expr: Expression, kinds: Mapping[str, str]) -> Compiled:
    """A function of (params, channels, temperatures); `kinds` maps every name read to parameter, channel or node."""
    return _compile(expr.tree, kinds)


def _compile(node: ast.expr, kinds: Mapping[str, str]) -> Compiled:
    if isinstance(node, ast.Constant):
        return _constant(float(node.value))
    if isinstance(node, ast.Name):
        return _leaf(node.id, kinds[node.id])
    if isinstance(node, ast.BinOp):
        op, left, right = _BINARY[type(node.op)], _compile(node.left, kinds), _compile(node.right, kinds)
        return lambda p, c, t: op(left(p, c, t), right(p, c, t))
    if isinstance(node, ast.UnaryOp):
        op, operand = _UNARY[type(node.op)], _compile(node.operand, kinds)
        return lambda p, c, t: op(operand(p, c, t))
    if isinstance(node, ast.Compare):  # 1.0 or 0.0, so that a comparison can be negated or subtracted like a number
        op, left = _COMPARE[type(node.ops[0])], _compile(node.left, kinds)
        right = _compile(node.comparators[0], kinds)
        return lambda p, c, t: np.asarray(op(left(p, c, t), right(p, c, t)), dtype=np.float64)
    function = FUNCTIONS[node.func.id][0]  # ast.Call: _check let nothing else through
    args = [_compile(a, kinds) for a in node.args]
    if node.func.id == "where":
        args[0] = _condition(node.args[0], kinds)
    if len(args) == 1:
        only = args[0]
        return lambda p, c, t: function(only(p, c, t))
    return lambda p, c, t: function(*(a(p, c, t) for a in args))


def _condition(node: ast.expr, kinds: Mapping[str, str]) -> Compiled:
    """where's condition: a comparison as booleans (what where reads; no round trip through 1.0/0.0), anything else
    as a number."""
    if isinstance(node, ast.Compare):
        op, left = _COMPARE[type(node.ops[0])], _compile(node.left, kinds)
        right = _compile(node.comparators[0], kinds)
        return lambda p, c, t: op(left(p, c, t), right(p, c, t))
    return _compile(node, kinds)


def _temperature_free(node: ast.expr, nodes: frozenset[str]) -> bool:
    return not any(isinstance(n, ast.Name) and n.id in nodes for n in ast.walk(node))


class NotAffine(ExpressionError):
    """A heat expression that is not affine in the node temperatures it names."""


def affine_parts(expr: Expression, kinds: Mapping[str, str]) -> tuple[Compiled, dict[str, Compiled]]:
    """Split q = q0 + Σ k_i·T_i: the temperature-free part q0 and each node's coefficient k_i (functions of
    params and channels). Raises NotAffine where a node temperature enters otherwise (T², exp(T), T·T, 1/T)."""
    nodes = frozenset(n for n, kind in kinds.items() if kind == "node")
    parts = _affine(expr.tree, kinds, nodes)
    zero = _constant(0.0)
    return parts.pop(None, zero), {k: v for k, v in parts.items()}


def _affine(node: ast.expr, kinds: Mapping[str, str], nodes: frozenset[str]) -> dict:
    """{None: temperature-free part, node: coefficient} of an affine tree, as compiled functions."""
    if _temperature_free(node, nodes):
        return {None: _compile(node, kinds)}
    if isinstance(node, ast.Name):  # a node temperature itself
        return {node.id: _constant(1.0)}
    if isinstance(node, ast.UnaryOp):
        op = _UNARY[type(node.op)]
        return {k: (lambda f: lambda p, c, t: op(f(p, c, t)))(f) for k, f in _affine(node.operand, kinds, nodes).items()}
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub)):
        left, right = _affine(node.left, kinds, nodes), _affine(node.right, kinds, nodes)
        op = _BINARY[type(node.op)]
        zero = _constant(0.0)
        return {k: (lambda a, b: lambda p, c, t: op(a(p, c, t), b(p, c, t)))(left.get(k, zero), right.get(k, zero))
                for k in dict.fromkeys([*left, *right])}
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Mult, ast.Div)):
        free_right = _temperature_free(node.right, nodes)
        if isinstance(node.op, ast.Mult) and not free_right and _temperature_free(node.left, nodes):
            scale, parts = _compile(node.left, kinds), _affine(node.right, kinds, nodes)
        elif free_right:
            scale, parts = _compile(node.right, kinds), _affine(node.left, kinds, nodes)
        else:
            raise NotAffine(f"a heat flow affine in the node temperatures, not {ast.unparse(node)[:60]!r}")
        op = _BINARY[type(node.op)] if free_right else operator.mul
        return {k: (lambda f: lambda p, c, t: op(f(p, c, t), scale(p, c, t)))(f) for k, f in parts.items()}
    if isinstance(node, ast.Call) and node.func.id == "where" and _temperature_free(node.args[0], nodes):
        cond = _condition(node.args[0], kinds)
        yes, no = _affine(node.args[1], kinds, nodes), _affine(node.args[2], kinds, nodes)
        zero = _constant(0.0)
        return {k: (lambda a, b: lambda p, c, t: np.where(cond(p, c, t), a(p, c, t), b(p, c, t)))(
            yes.get(k, zero), no.get(k, zero)) for k in dict.fromkeys([*yes, *no])}
    raise NotAffine(f"a heat flow affine in the node temperatures, not {ast.unparse(node)[:60]!r}")


#: The whitelist's functions in C (`benchlab deploy`): macros the generated module defines for its precision.
C_FUNCTIONS = {"exp": "BL_EXP", "log": "BL_LOG", "sqrt": "BL_SQRT", "abs": "BL_ABS", "minimum": "BL_MIN",
               "maximum": "BL_MAX"}
_C_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}
_C_COMPARE = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "=="}


def to_c(expr: Expression, name: Callable[[str], str]) -> str:
    """The expression as one C expression of the module's real type (`benchlab deploy`): `name` gives the C text of
    each name read (a parameter's value as a literal, a channel's or node's variable); numbers as `BL_R(…)`, a
    comparison as 1 or 0 like the numpy functions, `**` as BL_POW. The tree is the checked one: nothing else."""
    return _c(expr.tree, name)


def _c(node: ast.expr, name: Callable[[str], str]) -> str:
    if isinstance(node, ast.Constant):
        return f"BL_R({float(node.value)!r})"
    if isinstance(node, ast.Name):
        return name(node.id)
    if isinstance(node, ast.BinOp):
        left, right = _c(node.left, name), _c(node.right, name)
        if isinstance(node.op, ast.Pow):
            return f"BL_POW({left}, {right})"
        return f"({left} {_C_BINARY[type(node.op)]} {right})"
    if isinstance(node, ast.UnaryOp):
        return f"({'-' if isinstance(node.op, ast.USub) else '+'}{_c(node.operand, name)})"
    if isinstance(node, ast.Compare):
        test = f"{_c(node.left, name)} {_C_COMPARE[type(node.ops[0])]} {_c(node.comparators[0], name)}"
        return f"(({test}) ? BL_R(1.0) : BL_R(0.0))"
    if node.func.id in SEQUENTIAL:
        raise ExpressionError(f"a law without {node.func.id}(...): its switch state is not carried by the C module yet")
    args = [_c(a, name) for a in node.args]  # ast.Call: _check let nothing else through
    if node.func.id == "where":
        test = node.args[0]
        condition = (f"{_c(test.left, name)} {_C_COMPARE[type(test.ops[0])]} {_c(test.comparators[0], name)}"
                     if isinstance(test, ast.Compare) else f"{args[0]} != BL_R(0.0)")
        return f"(({condition}) ? {args[1]} : {args[2]})"
    return f"{C_FUNCTIONS[node.func.id]}({', '.join(args)})"
