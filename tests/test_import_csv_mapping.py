"""A CSV with its own column names (`Zeit [s]`, `T_Luft [°C]`) is mapped by the mapping file MDF files and CAN
logs use, and a CSV or MDF without the required channels names them and what the file offers (issue 46)."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from benchlab.cli import main
from benchlab.commands.import_csv import read_csv
from benchlab.importing.mapping import Mapped

#: A German bench recorder's columns for the clutch channels (docs/contract.md §1), three rows.
GERMAN = {"Zeit [s]": "time", "n_Motor [1/min]": "engine_speed", "n_Getriebe [U/min]": "clutch_speed",
          "M_Kupplung [Nm]": "clutch_torque", "KU_Zustand [-]": "clutch_state", "P_Reib [kW]": "friction_power",
          "T_Schwungrad [°C]": "T_flywheel", "T_Luft [°C]": "T_air", "T_Gehaeuse [K]": "T_housing",
          "T_Umgebung [°C]": "T_ambient"}
ROWS = ["0,0;1500;1400;20;1;0,5;30,0;22,0;300,15;20,0", "0,5;1500;1400;20;1;0,5;30,5;22,0;300,15;20,0",
        "1,0;1500;1400;20;1;0,5;31,0;22,0;300,15;20,0"]


def _csv(tmp_path: Path) -> Path:
    path = tmp_path / "pruefstand.csv"
    path.write_text(";".join(GERMAN) + "\n" + "\n".join(ROWS) + "\n", encoding="utf-8")
    return path


def _mapping(tmp_path: Path, skip: str = "") -> Path:
    lines = [f'{channel} = "{title.partition(" [")[0]}"' for title, channel in GERMAN.items() if channel != skip]
    path = tmp_path / "map.toml"
    path.write_text("[channels]\n" + "\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_a_csv_of_its_own_names_is_mapped_with_units_scale_and_time(tmp_path: Path):
    mapped = [Mapped("time", "Zeit"), Mapped("T_air", "T_Luft [°C]"), Mapped("T_housing", "T_Gehaeuse"),
              Mapped("engine_speed", "n_Motor", unit="rad/s", scale=2.0, offset=1.0)]
    frame, dt, units = read_csv(_csv(tmp_path), required=("T_air",), mapped=mapped, sep=";")
    assert {"time", "T_air", "T_housing", "engine_speed"} <= set(frame.columns)
    assert np.isclose(dt, 0.5) and units["T_air"] == "degC" and np.allclose(frame["T_air"], 22.0)
    assert units["T_housing"] == "degC" and np.allclose(frame["T_housing"], 27.0)       # 300.15 K
    assert np.allclose(frame["engine_speed"], 3001.0 * 60 / (2 * np.pi))               # (1500·2+1) rad/s in rpm
    assert frame.attrs["mapped_from"]["T_air"] == "T_Luft [°C]"


def test_benchlab_import_maps_a_csv_and_a_missing_column_is_named(tmp_path: Path, refused):
    csv, out = _csv(tmp_path), tmp_path / "run.h5"
    assert main(["import", str(csv), "--mapping", str(_mapping(tmp_path)), "--out", str(out)]) == 0
    with h5py.File(out) as f:
        assert f["aligned/T_air"].attrs["units"] == "degC" and np.allclose(f["aligned/T_air"][:], 22.0)
        assert np.allclose(f["aligned/friction_power"][:], 500.0)                         # kW in W
    refused(["import", str(csv), "--mapping", str(_mapping(tmp_path, skip="T_ambient")), "--out",
             str(tmp_path / "r2.h5")], "column T_ambient", "required", "T_Umgebung", "n_Motor")
    refused(["import", str(csv), "--out", str(tmp_path / "r3.h5")], "column time, engine_speed", "Zeit", "T_Luft")
    (tmp_path / "typo.toml").write_text('[channels]\nT_air = "T_Luftt"\n', encoding="utf-8")
    refused(["import", str(csv), "--mapping", str(tmp_path / "typo.toml"), "--out", str(tmp_path / "r4.h5")],
            "mapping channels.T_air", "T_Luftt")
