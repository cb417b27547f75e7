"""Identify two run files with the linear model and hold the second's parameters to the first's standard errors:
the test of an import that loses nothing the identification needs."""

from __future__ import annotations

import json
from pathlib import Path

from benchlab.cli import main


def assert_same_parameters(folder: Path, reference: Path, other: Path) -> None:
    """`other` identifies to `reference`'s parameters, each within its standard error from `reference`."""
    fits = []
    for path in (reference, other):
        out = folder / f"{path.stem}.params.json"
        assert main(["identify", str(path), "--model", "linear", "--out", str(out), "-q"]) == 0
        fits.append(json.loads(out.read_text()))
    for name, value in fits[0]["params"].items():
        assert abs(fits[1]["params"][name] - value) <= fits[0]["uncertainty"][name], name
