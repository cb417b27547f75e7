"""The residual line of `benchlab identify` names the test that decided "not white" (issue 46: "not white (Ljung-Box
p 0.503)" read as a contradiction when the excess over the white noise had decided it)."""

from __future__ import annotations

import re

import numpy as np

from benchlab.commands.identify import whiteness_verdict
from benchlab.identify.residuals import residual_tests


def _tests(offset_K: float, seed: int = 3) -> dict:
    noise = np.random.default_rng(seed).normal(0.0, 0.05, 6000)  # 6000 s at 1 s: 100 windows of 60 s
    return residual_tests(noise + offset_K, {}, step_s=1.0)


def test_white_noise_reads_white_with_both_p_values():
    tests = _tests(0.0)
    line = whiteness_verdict(tests)
    assert tests["white"] and line.startswith("white (") and "Ljung-Box p" in line and "excess over white noise p" in line


def test_an_offset_is_not_white_by_the_excess_test_and_the_line_names_that_test():
    tests = _tests(0.5)  # a constant bias: its window means are uncorrelated (Ljung-Box content), their size is not
    line = whiteness_verdict(tests)
    assert not tests["white"] and line.startswith("not white (")
    rejected_by = line.split("rejected by ")[1]
    named = dict(re.findall(r"(Ljung-Box|excess over white noise) p <?([0-9.]+)", rejected_by))
    assert named and all(float(p) < tests["alpha"] / 2 for p in named.values())
    assert ("Ljung-Box" in named) == (tests["ljung_box_p"] < tests["alpha"] / 2)
    assert "excess over white noise" in named
