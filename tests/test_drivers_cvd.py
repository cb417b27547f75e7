"""Callendar–Van Dusen: IEC 60751 reference values, round trips, per-sensor coefficients."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers import cvd


@pytest.mark.parametrize("t, r", [(0.0, 1000.0), (100.0, 1385.055), (-50.0, 803.063), (-200.0, 185.201),
                                  (850.0, 3904.811), (25.0, 1097.347)])
def test_reference_values(t: float, r: float) -> None:
    assert cvd.resistance(t) == pytest.approx(r, abs=1e-3)
    assert cvd.temperature(r) == pytest.approx(t, abs=2e-3)


def test_round_trip_whole_range_vectorised() -> None:
    t = np.linspace(cvd.T_MIN_C, cvd.T_MAX_C, 20001)
    r = cvd.resistance(t)
    assert isinstance(r, np.ndarray) and r.shape == t.shape
    assert np.max(np.abs(cvd.temperature(r) - t)) < 1e-9


def test_scalar_in_scalar_out() -> None:
    assert isinstance(cvd.temperature(1100.0), float)
    assert isinstance(cvd.resistance(20), float)
    assert cvd.in_range(20.0) is True and cvd.in_range(900.0) is False


def test_calibrated_coefficients() -> None:
    coef = cvd.CvdCoefficients(r0=1000.42, a=3.9080e-3, b=-5.80e-7)
    r = cvd.resistance(60.0, coef)
    assert r != pytest.approx(cvd.resistance(60.0), abs=0.01)
    assert cvd.temperature(r, coef) == pytest.approx(60.0, abs=1e-9)
    assert cvd.temperature(r) != pytest.approx(60.0, abs=0.05)


@settings(max_examples=200, deadline=None)
@given(st.floats(min_value=-200.0, max_value=850.0))
def test_round_trip_property(t: float) -> None:
    assert cvd.temperature(cvd.resistance(t)) == pytest.approx(t, abs=1e-9)


def test_monotonic() -> None:
    r = cvd.resistance(np.linspace(-200, 850, 5000))
    assert np.all(np.diff(r) > 0)


@settings(max_examples=300, deadline=None)
@given(st.floats(min_value=0.0, max_value=5000.0))
def test_scalar_and_vector_paths_agree(r: float) -> None:
    vector = cvd.temperature(np.array([r]))[0]
    assert cvd.temperature(r) == pytest.approx(vector, abs=1e-9, nan_ok=True)
