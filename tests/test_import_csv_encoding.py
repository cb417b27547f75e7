"""A CSV saved by German Excel (Windows-1252, `°` as the byte 0xB0) is read, and the import says in which encoding
(issue 46); UTF-8 stays the first reading."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchlab.commands.import_csv import csv_text, read_csv

TABLE = "time [s];T_air [°C]\n0,0;20,5\n0,1;20,6\n0,2;20,7\n"


def test_a_windows_1252_csv_is_read_with_its_degree_sign(tmp_path: Path):
    path = tmp_path / "excel.csv"
    path.write_bytes(TABLE.encode("cp1252"))
    assert b"\xb0" in path.read_bytes()
    frame, dt, units = read_csv(path, required=())
    assert frame.attrs["encoding"] == "Windows-1252"
    assert units["T_air"] == "degC" and np.allclose(frame["T_air"], [20.5, 20.6, 20.7])
    assert np.isclose(dt, 0.1)


def test_utf8_comes_first_and_keeps_its_characters(tmp_path: Path):
    path = tmp_path / "utf8.csv"
    path.write_bytes(TABLE.encode("utf-8"))  # "°" as 0xC2 0xB0: read as cp1252 it would be "Â°"
    assert csv_text(path) == (TABLE, "UTF-8")
