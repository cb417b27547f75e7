"""Field checks of user files in one home (issue 17): benchlab.values' number checks and its unknown-key check,
and the modules that now go through them. Each bad value is one InputError naming the field; none is a crash."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from benchlab.errors import InputError
from benchlab.model.catalog import builtin
from benchlab.model.definition import parse_model
from benchlab.observer.noise import check_positive, residual_rms
from benchlab.model.params import paper_params
from benchlab.report.resistance import standard_errors
from benchlab.values import check_keys
from benchlab.wear.clutchfile import DEFAULT_DOC, clutch_from_doc
from benchlab.wear.thermal import heat_split
from protocols.limits import MAX_AGE_LIMIT_S, BenchLimits

HUGE = 10 ** 400  # TOML and JSON integers have any size; float() of this overflows
NOT_FINITE = [True, HUGE, -HUGE, math.nan, math.inf, "0.5", None]


def test_check_keys_names_the_first_unknown_key_and_lists_the_known_ones():
    check_keys("f.toml", "acquisition", {"dt": 0.01, "tick_s": 0.1}, ("dt", "tick_s"))  # all known: no error
    with pytest.raises(InputError) as exc:
        check_keys("f.toml", "acquisition", {"dt": 0.01, "tick": 0.1, "other": 1}, ("dt", "tick_s"))
    assert (exc.value.source, exc.value.field) == ("f.toml", "acquisition.tick")
    assert exc.value.expected == "one of dt, tick_s (unknown key)"


def test_check_keys_without_a_prefix_names_the_key_alone():
    with pytest.raises(InputError) as exc:
        check_keys("f.toml", "", {"drivetrane": {}}, ("drivetrain", "limits"))
    assert exc.value.field == "drivetrane" and str(exc.value) == \
        "f.toml: drivetrane: one of drivetrain, limits (unknown key)"


def test_model_files_and_limits_refuse_unknown_keys_in_the_same_form():
    doc = builtin("linear").to_doc()
    doc["parameters"]["C_P"]["strat"] = 1.0
    with pytest.raises(InputError) as model:
        parse_model(doc, "m.toml")
    with pytest.raises(InputError) as limits:
        BenchLimits.from_mapping({"max_air": 80.0}, "b.toml")
    assert model.value.field == "parameters.C_P.strat" and limits.value.field == "limits.max_air"
    for exc in (model.value, limits.value):
        assert exc.expected.startswith("one of ") and exc.expected.endswith(" (unknown key)")
    assert "start, min, max" in model.value.expected


@pytest.mark.parametrize("value", [*NOT_FINITE, -0.1, 1.5])
def test_heat_split_outside_zero_to_one_is_refused(value):
    params = paper_params()
    params.extra = {"split": value}
    with pytest.raises(InputError) as exc:
        heat_split(params, "p.json")
    assert exc.value.field == "split" and f"got {value!r}" in exc.value.expected


@pytest.mark.parametrize("value, expected", [(0, 0.0), (1, 1.0), (0.3, 0.3)])
def test_heat_split_in_zero_to_one_is_a_float(value, expected):
    params = paper_params()
    params.extra = {"split": value}
    split = heat_split(params)
    assert split == expected and type(split) is float


@pytest.mark.parametrize("key, value", [("wear_plate_mm", HUGE), ("wear_plate_mm", math.inf), ("wear_plate_mm", -1),
                                        ("wear_flywheel_mm", True), ("loss_plate", 1.0), ("loss_flywheel", math.nan)])
def test_clutch_file_state_not_a_number_in_range_is_refused(key, value):
    doc = {**DEFAULT_DOC, "state": {**DEFAULT_DOC["state"], key: value}}
    with pytest.raises(InputError) as exc:
        clutch_from_doc(doc, "c.toml")
    assert exc.value.field == f"state.{key}" and f"got {value!r}" in exc.value.expected


def test_clutch_file_state_in_range_is_kept():
    doc = {**DEFAULT_DOC, "state": {**DEFAULT_DOC["state"], "wear_plate_mm": 1, "loss_flywheel": 0.5}}
    state = clutch_from_doc(doc, "c.toml").initial
    assert (state.wear_plate_mm, state.loss_flywheel) == (1.0, 0.5)


@pytest.mark.parametrize("value", [*NOT_FINITE, 0, -2.0])
def test_noise_figure_not_positive_is_refused(value):
    with pytest.raises(InputError) as exc:
        check_positive("command line", "--initial-std", value, "K")
    assert exc.value.field == "--initial-std" and exc.value.expected == f"a positive noise in K, got {value!r}"


def test_noise_figure_positive_is_a_float():
    assert check_positive("command line", "--initial-std", 2, "K") == 2.0


def test_residual_statistics_use_positive_finite_numbers_only():
    runs = {f"run{i}": {"channels": {"T_air": {"rmse_K": value}}} for i, value in enumerate([0.3, 0.4, *NOT_FINITE, 0])}
    assert residual_rms({"fit": {"fitting": runs}}, "T_air") == pytest.approx(math.sqrt((0.3 ** 2 + 0.4 ** 2) / 2))
    assert residual_rms({"fit": {"fitting": {"run": {"channels": {"T_air": {"rmse_K": HUGE}}}}}}, "T_air") is None


def test_standard_errors_keep_finite_numbers_only():
    params = paper_params()
    params.extra = {"uncertainty": {"R0": 0.01, "a1": -0.02, "b1": HUGE, "a2": True, "b2": math.nan, "C_P": "5"}}
    assert standard_errors(params) == {"R0": 0.01, "a1": -0.02}


@pytest.mark.parametrize("value", [*NOT_FINITE, 0, -1.0, MAX_AGE_LIMIT_S * 1.01])
def test_limits_age_outside_its_range_is_refused(value):
    with pytest.raises(InputError) as exc:
        BenchLimits.from_mapping({"max_age_s": {"T_air": value}}, "b.toml")
    assert exc.value.field == "limits.max_age_s.T_air" and f"got {value!r}" in exc.value.expected


def test_limits_age_at_its_bound_is_kept():
    assert BenchLimits.from_mapping({"max_age_s": {"T_air": int(MAX_AGE_LIMIT_S)}}).max_age_s["T_air"] == MAX_AGE_LIMIT_S


def test_the_one_line_form_holds_for_a_key_with_a_line_break(tmp_path: Path):
    with pytest.raises(InputError) as exc:
        check_keys(tmp_path / "b.toml", "node", {"period_s\nx": 1}, ("period_s",))
    assert "\n" not in str(exc.value) and "node.period_s\\nx" in str(exc.value)
