"""Units as engineers write them (`°C`, `K`, `Nm`, `N·m`, `1/min`, `U/min`, `rad/s`, `kW`, `ms`, …), read through
one pint registry and converted to the unit a run file stores (the contract's spelling: `degC`, `N*m`, `rpm`).

The one home of unit spellings and conversions: `benchlab import` (CSV, MDF) converts every channel with it and
`benchlab.runfile` checks stored units with it. pint loads on first use (about 0.25 s), never for a unit that is
already spelled as the contract spells it.
"""

from __future__ import annotations

import re
from functools import lru_cache
from typing import Any

import numpy as np

from benchlab.errors import InputError

#: Spellings pint reads otherwise than a test engineer means them: `Nm` is a newton metre (not pint's "number
#: metre"), and a plain reciprocal time (`1/min`, `U/min`, `min^-1`) counts revolutions (not radians).
_ENGINEERS = (
    (re.compile(r"(?<![A-Za-z])([kM]?)Nm(?![A-Za-z])"), r"\1N*m"),
    (re.compile(r"(?<![\w.])(?:1|U|r|rev)\s*/\s*(min|s)\b"), r"revolution/\1"),
    (re.compile(r"(?<![\w.])U[pP][mM](?!\w)"), "rpm"),  # German "Umdrehungen pro Minute"
    (re.compile(r"(?<![\w.])(min|s)\s*(?:\^|\*\*)?\s*(?:-1|⁻¹)(?![\d])"), r"revolution/\1"),
    (re.compile(r"℃"), "degC"),
    (re.compile(r"^\s*-\s*$"), ""),
)
#: The grammar a unit's text must follow before pint sees it (pint evaluates what it reads: `10**10**10*K` never
#: ends, 5000 parentheses exhaust its recursion): names of letters (a leading `°`, `%`), numbers of at most 6 digits
#: (no exponent), `*`, `/`, `·`, spaces, small literal integer powers (`^2`, `**-1`, `²`, `⁻¹`) and parentheses at
#: most MAX_UNIT_DEPTH deep, MAX_UNIT_CHARS characters in all.
MAX_UNIT_CHARS = 64
MAX_UNIT_DEPTH = 3
_UNIT_TOKEN = re.compile(r"""\s*(?:
    (?P<name>[^\W\d_][^\W_]{0,31}|[°%℃][^\W\d_]{0,31})
  | (?P<number>\d{1,6}(?:\.\d{1,6})?)(?![\w.])
  | (?P<power>(?:\^|\*\*)\s*-?[1-9](?!\d)|⁻?[¹²³⁴⁵⁶⁷⁸⁹](?![⁰¹²³⁴⁵⁶⁷⁸⁹]))
  | (?P<op>[*/·⋅])
  | (?P<open>\()
  | (?P<close>\))
)""", re.VERBOSE)


def unit_problem(unit: str) -> str | None:
    """Why `unit` is no unit text benchlab reads (its grammar above), or None where it follows the grammar.
    The gate before pint: a bomb or markup is refused here, never evaluated."""
    text = unit.strip()
    if not text or text == "-":
        return None
    if len(text) > MAX_UNIT_CHARS:
        return f"at most {MAX_UNIT_CHARS} characters"
    depth, position, operand = 0, 0, False
    while position < len(text):
        token = _UNIT_TOKEN.match(text, position)
        if token is None or token.end() == position:
            return f"names, numbers, *, /, ^ and parentheses only (at {text[position:position + 10].strip()!r})"
        kind = token.lastgroup
        if kind in ("power", "op", "close") and not operand:
            return "*, /, a power or a closing parenthesis after a name, a number or parentheses"
        depth += {"open": 1, "close": -1}.get(kind or "", 0)
        if not 0 <= depth <= MAX_UNIT_DEPTH:
            return f"balanced parentheses at most {MAX_UNIT_DEPTH} deep"
        operand = kind in ("name", "number", "close", "power")
        position = token.end()
    if not operand:
        return "a name, a number or parentheses at the end"
    return "balanced parentheses" if depth else None


#: What a dimension is called in a message, by a unit of it.
_KINDS = {"degC": "temperature", "N*m": "torque", "rpm": "rotational speed", "W": "power", "s": "time",
          "1": "number"}


#: How a stored unit is shown to people (figures, pages): the contract's spellings are ASCII for files and code.
DISPLAY = {"degC": "°C", "N*m": "N·m", "um": "µm", "1": "-"}


def display(unit: str) -> str:
    """`unit` as a figure or a page shows it (`degC` → `°C`, `N*m` → `N·m`); a file keeps the stored spelling."""
    return DISPLAY.get(unit, unit)


class UnitMismatch(ValueError):
    """A unit that is unknown or of another dimension than the one expected; str() says what was expected."""


def _engineers(text: str) -> str:
    """`text` with the spellings of _ENGINEERS replaced by pint's."""
    for pattern, replacement in _ENGINEERS:
        text = pattern.sub(replacement, text)
    return text


@lru_cache(maxsize=1)
def registry() -> Any:
    """The one pint UnitRegistry (engineers' spellings read as above)."""
    import pint

    return pint.UnitRegistry(preprocessors=[_engineers], autoconvert_offset_to_baseunit=True)


@lru_cache(maxsize=256)
def _parsed(unit: str) -> Any:
    """`unit` as a pint Unit (empty: dimensionless), None where it breaks the grammar (unit_problem), pint does not
    read it (an arithmetic or recursion error included) or its scale is not a finite positive number."""
    import pint

    if unit_problem(unit) is not None:
        return None
    try:
        parsed = registry().parse_units(unit.strip()) if unit.strip() else registry().dimensionless
        scale = float(registry().Quantity(1.0, parsed).to_base_units().magnitude)
    except (pint.errors.PintError, AttributeError, TypeError, ValueError, SyntaxError, ArithmeticError,
            RecursionError):
        return None
    return parsed if np.isfinite(scale) and scale > 0 else None


def _kind(parsed: Any) -> str:
    """`temperature`, `torque`, … or the dimension itself."""
    found = (kind for unit, kind in _KINDS.items() if _parsed(unit).dimensionality == parsed.dimensionality)
    return next(found, f"dimension {parsed.dimensionality}")


def _check(unit: str, target: str) -> tuple[Any, Any]:
    """`unit` and `target` parsed; UnitMismatch where `unit` is unknown or of another dimension."""
    source, wanted = _parsed(unit), _parsed(target)
    if wanted is None:
        raise ValueError(f"not a unit: {target!r}")
    if source is None:
        why = unit_problem(unit) or "not a unit pint knows"
        raise UnitMismatch(f"{target} or a unit convertible to it, got {unit!r} ({why})")
    if source.dimensionality != wanted.dimensionality:
        raise UnitMismatch(f"{target} ({_kind(wanted)}) or a unit convertible to it, got {unit!r} "
                           f"({_kind(source)})")
    return source, wanted


def same(unit: str, target: str) -> bool:
    """Whether `unit` is `target` spelled another way (`°C` for `degC`, `Nm` for `N*m`): values need no change.
    A unit of the same dimension with another scale or zero (`K`, `rad/s`) is not the same."""
    if unit == target:
        return True
    source, wanted = _parsed(unit), _parsed(target)
    if source is None or wanted is None or source.dimensionality != wanted.dimensionality:
        return False
    q = registry().Quantity(np.array([0.0, 1.0]), source).to(wanted).magnitude
    return bool(np.allclose(q, [0.0, 1.0], rtol=1e-12, atol=1e-12))


def convert(values: np.ndarray, unit: str, target: str) -> np.ndarray:
    """`values` in `unit` as float64 in `target` (temperatures with their offsets); UnitMismatch where `unit` is
    not a unit or not of `target`'s dimension. NaN (not measured) stays NaN."""
    values = np.asarray(values, dtype=np.float64)
    if unit == target:
        return values
    source, wanted = _check(unit, target)
    return np.asarray(registry().Quantity(values, source).to(wanted).magnitude, dtype=np.float64)


def _canonical(unit: str) -> str:
    """The spelling a run file stores a channel's unit in: the contract's where `unit` is one of its units spelled
    another way (`°C` → `degC`, `Nm` → `N*m`, `1/min` → `rpm`), else `unit` as given."""
    from benchlab.runfile.schema import ALIGNED_UNITS

    return next((c for c in dict.fromkeys(ALIGNED_UNITS.values()) if same(unit, c)), unit)


def to_stored(source: object, field: str, name: str, values: np.ndarray, unit: str) -> tuple[np.ndarray, str]:
    """A channel's values and the unit a run file stores them in: a contract channel (`T_air`, …) converted to the
    contract's unit, any other temperature to degC (every temperature a model reads is in degC), any other channel
    as given, its unit in the contract's spelling where it is one of the contract's units. InputError on `field` of
    `source` for a unit that is not its contract unit's dimension, or no unit at all (unit_problem, pint)."""
    from benchlab.runfile.schema import ALIGNED_UNITS

    target = ALIGNED_UNITS.get(name)
    if target is None:
        parsed = _parsed(unit)
        if parsed is None:
            problem = unit_problem(unit)
            raise InputError(str(source), field, f"{name} in a unit ({problem or 'one pint knows'}), got {unit!r}")
        if parsed.dimensionality != _parsed("degC").dimensionality:
            return np.asarray(values, dtype=np.float64), _canonical(unit)
        target = "degC"
    try:
        return convert(values, unit, target), target
    except UnitMismatch as exc:
        raise InputError(str(source), field, f"{name} in {exc}") from None
