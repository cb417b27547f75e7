"""`benchlab export`: a run file reopened as MDF4 by asammdf, as CSV by pandas, as Parquet by pyarrow."""

from __future__ import annotations

import sys

import h5py
import numpy as np
import pandas as pd
import pytest
from asammdf import MDF

from benchlab.acquire import AlignedSource, Layout, StreamSpec
from benchlab.cli import main
from benchlab.importing.mdf import numbers
from benchlab.runfile import ALIGNED_UNITS, REQUIRED, load_run, read_progress
from benchlab.runner.session import RunRequest, execute
from protocols.schedule import Step

from crashed import write_then_kill  # tests/crashed.py

#: Ten seconds of bench: idle, one launch, open again; every raw stream and a few events.
STEPS = (Step("open", 3.0, 1500.0, 0.0, 0.0, 0), Step("launch", 4.0, 1500.0, 60.0, 100.0, 1),
         Step("open", 3.0, 1500.0, 0.0, 100.0, 1))


@pytest.fixture(scope="module")
def bench_run(tmp_path_factory):
    """A run file written by the runner on the simulated bench: /aligned, /raw/<stream>, /events."""
    path = tmp_path_factory.mktemp("export") / "run.h5"
    code, _ = execute(RunRequest("custom", path, steps=STEPS, install_signals=False))
    assert code == 0
    return path


def _values(mdf, name):
    """A channel's stored numbers (enums before their texts) with its invalid samples as NaN, and the signal."""
    sig, values = numbers(mdf, name=name)
    return values, sig


def _one_line_exit_2(argv, capsys, *words):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    for word in words:
        assert word in err
    return err


def test_mf4_holds_every_group_at_its_own_time_base_with_units(bench_run, tmp_path, capsys):
    out = tmp_path / "run.mf4"
    assert main(["export", str(bench_run), "--to", str(out)]) == 0
    assert str(out) in capsys.readouterr().out
    mdf = MDF(out)
    try:
        names = [ch.name for group in mdf.groups for ch in group.channels]
        assert len(names) == len(set(names))  # unique across the file, masters included
        acq = [group.channel_group.acq_name for group in mdf.groups]
        with h5py.File(bench_run, "r") as f:
            streams = list(f["raw"])
            assert acq == ["/aligned", *(f"/raw/{s}" for s in streams), "/events"]
            for name, ds in f["aligned"].items():
                values, sig = _values(mdf, name)
                np.testing.assert_array_equal(values, ds[()])
                np.testing.assert_array_equal(sig.timestamps, f["aligned/time"][()])
                assert sig.unit == ds.attrs["units"]
            assert "ϑ_F" in mdf.get("T_flywheel").comment and "node.T_flywheel_1" in mdf.get("T_flywheel_1").comment
            for name, ds in f["aligned"].items():  # one home: the run file's own descriptions are what MDF shows
                assert name == "time" or ds.attrs["description"] == mdf.get(name).comment != "", name
            for stream in streams:
                group = f["raw"][stream]
                order = np.argsort(group["time"][()], kind="stable")
                for column, ds in group.items():
                    if column == "time":
                        continue
                    values, sig = _values(mdf, f"{stream}.{column}")  # enums: the numbers before the texts
                    np.testing.assert_array_equal(values, ds[()][order])
                    np.testing.assert_array_equal(sig.timestamps, group["time"][()][order])
                    assert sig.unit == ds.attrs["units"]
            kinds = mdf.get("events.kind")
            np.testing.assert_array_equal(kinds.samples, f["events/kind"][()])
            np.testing.assert_array_equal(kinds.timestamps, f["events/time"][()])
            np.testing.assert_array_equal(mdf.get("events.cycle").samples, f["events/cycle"][()])
            reasons = mdf.get("events.reason").samples
            np.testing.assert_array_equal(reasons, f["events/reason"][()])
            # and each row an MDF event (mdf.events): a marker at its time, named by its kind
            assert [e.name for e in mdf.events] == [k.decode() for k in f["events/kind"][()]]
            np.testing.assert_allclose([e.value for e in mdf.events], f["events/time"][()], rtol=1e-12)
            details = [d.decode() for d in f["events/detail"][()]]
            assert all(d in e.comment for d, e in zip(details, mdf.events))
        # enums show the DBC's value tables (VAL_): the launch slips, every controller runs
        assert {b"Open", b"Slipping"} <= set(mdf.get("can_clutch.clamp_state").samples)
        assert {b"Running"} == set(mdf.get("can_drive.state").samples) & {b"Running", b"Fault"}
        assert b"None" in set(mdf.get("can_load.fault_code").samples)
        assert "run_complete" in {k.decode() for k in kinds.samples}
        assert {"synchronised", "time"} & {r.decode() for r in reasons}  # the launch's and the steps' ends
        assert 'name="schema">benchlab-run/1<' in mdf.header.comment
        # not measured: an invalidation bit (the flywheel node's first readings come after the grid's first rows);
        # enums and counters as integers; CAN channels name their message and sending node
        temperature = mdf.get("T_flywheel", ignore_invalidation_bits=True)
        assert temperature.invalidation_bits is not None and temperature.invalidation_bits.any()
        assert len(mdf.get("T_flywheel").samples) == (~np.asarray(temperature.invalidation_bits)).sum()
        for name in ("can_clutch.clamp_state", "can_drive.fault_code", "node.seq", "clutch_state"):
            assert mdf.get(name, raw=True).samples.dtype.kind in "iu", name
        clamp = mdf.get("can_clutch.clamp_state")
        assert clamp.source.name == "ClutchActuator" and "ClutchActuator_Status" in clamp.source.path
    finally:
        mdf.close()


def test_mf4_of_a_crashed_run_stops_at_its_progress_record(tmp_path):
    channels = {k: ALIGNED_UNITS[k] for k in REQUIRED if k != "time"}
    layout = Layout((StreamSpec("bench", tuple(channels.items()), 50.0, 0.05),),
                    tuple(AlignedSource(k, "bench", k) for k in channels), channels, None, 0.01)
    run = tmp_path / "crashed.h5"
    calls: list[tuple] = [("event", (0.5, "cycle_start", 0), {"step": 2})]
    for k in range(1, 151):
        calls += [("add", ("bench", k * 0.02, [0.0 if c == "clutch_state" else 20.0 + k for c in channels])),
                  ("advance", (k * 0.02,))]
    write_then_kill(run, layout, calls, protocol="custom", planned_s=600.0)  # room for 10 minutes, data for 3 s
    with h5py.File(run, "r") as f:
        progress = read_progress(f)
        assert f.attrs["status"] == "running" and f["aligned/time"].shape[0] > 10 * progress["aligned_rows"]
    out = tmp_path / "crashed.mf4"
    assert main(["export", str(run), "--to", str(out)]) == 0
    mdf = MDF(out)
    try:
        assert len(mdf.get("engine_speed", ignore_invalidation_bits=True).samples) == progress["aligned_rows"]
        speed = mdf.get("bench.engine_speed")
        assert len(speed.samples) == progress["rows/bench"] == 150 and np.isfinite(speed.timestamps).all()
        assert list(mdf.get("events.kind").samples) == [b"cycle_start"]
        step = mdf.get("events.step")
        assert list(step.samples) == [2] and step.unit == "1"
    finally:
        mdf.close()


def test_csv_opens_in_pandas_with_units_in_the_header(run_file, tmp_path):
    out = tmp_path / "run.csv"
    assert main(["export", str(run_file), "--to", str(out)]) == 0
    run = load_run(run_file)
    table = pd.read_csv(out)
    assert list(table.columns) == [f"{c} [{run.attrs['units'][c]}]" for c in run.columns]
    for c in run.columns:
        np.testing.assert_array_equal(table[f"{c} [{run.attrs['units'][c]}]"].to_numpy(), run[c].to_numpy())


def test_parquet_opens_in_pandas_with_units_in_the_schema(run_file, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    out = tmp_path / "run.parquet"
    assert main(["export", str(run_file), "--to", str(out)]) == 0
    run = load_run(run_file)
    table = pd.read_parquet(out)
    assert list(table.columns) == list(run.columns)
    pd.testing.assert_frame_equal(table, pd.DataFrame(run), check_like=False)
    schema = pq.read_schema(out)
    for c in run.columns:
        assert schema.field(c).metadata[b"unit"].decode() == run.attrs["units"][c]
    assert b"benchlab-run/1" in schema.metadata[b"benchlab"]


def test_csv_goes_back_into_a_run_file_with_import(run_file, tmp_path):
    csv, back = tmp_path / "run.csv", tmp_path / "back.h5"
    assert main(["export", str(run_file), "--to", str(csv)]) == 0
    assert main(["import", str(csv), "--out", str(back)]) == 0
    before, after = load_run(run_file), load_run(back)
    for c in before.columns:
        np.testing.assert_allclose(after[c].to_numpy(), before[c].to_numpy(), rtol=1e-15, atol=0)
    assert after.attrs["bench"] == "imported"  # the file says it came through import, not from a bench run


def test_bad_targets_and_inputs_are_one_line_exit_2(run_file, tmp_path, capsys):
    _one_line_exit_2(["export", str(run_file), "--to", str(tmp_path / "run.xlsx")], capsys, "--to", ".mf4")
    _one_line_exit_2(["export", str(tmp_path / "none.h5"), "--to", str(tmp_path / "a.mf4")], capsys, "not found")
    junk = tmp_path / "junk.h5"
    junk.write_text("not hdf5")
    _one_line_exit_2(["export", str(junk), "--to", str(tmp_path / "a.csv")], capsys, "junk.h5", "HDF5")
    plain = tmp_path / "plain.h5"
    with h5py.File(plain, "w") as f:
        f["x"] = np.arange(3.0)
    _one_line_exit_2(["export", str(plain), "--to", str(tmp_path / "a.mf4")], capsys, "plain.h5", "schema")
    assert not any(tmp_path.glob("a.*")) and not any(tmp_path.glob(".a.*"))


def test_an_existing_output_needs_force(run_file, tmp_path, capsys):
    out = tmp_path / "run.csv"
    out.write_text("keep me\n")
    _one_line_exit_2(["export", str(run_file), "--to", str(out)], capsys, "--force")
    assert out.read_text() == "keep me\n"
    assert main(["export", str(run_file), "--to", str(out), "--force"]) == 0
    assert out.read_text().startswith("time [s],")


def test_parquet_without_pyarrow_says_what_to_install(run_file, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # import pyarrow now raises ImportError
    out = tmp_path / "run.parquet"
    _one_line_exit_2(["export", str(run_file), "--to", str(out)], capsys, "pyarrow", "benchlab[export]")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.h5"]  # no output, no half-made copy


def test_mf4_of_a_simulate_output_puts_model_beside_measurement(run_file, params_file, tmp_path):
    sim, out = tmp_path / "sim.h5", tmp_path / "sim.mf4"
    assert main(["simulate", str(run_file), "--params", str(params_file), "--out", str(sim)]) == 0
    assert main(["export", str(sim), "--to", str(out)]) == 0
    mdf = MDF(out)
    try:
        assert [g.channel_group.acq_name for g in mdf.groups] == ["/aligned", "/simulated"]
        with h5py.File(sim, "r") as f:
            for name in ("T_flywheel", "T_pressure_plate"):
                model, sig = _values(mdf, f"simulated.{name}")
                np.testing.assert_array_equal(model, f["simulated"][name][()])
                assert sig.unit == "degC"
            np.testing.assert_array_equal(_values(mdf, "T_flywheel")[0], f["aligned/T_flywheel"][()])
    finally:
        mdf.close()


def test_mf4_of_a_bench_run_goes_back_into_a_run_file_with_its_enums_as_numbers(bench_run, tmp_path):
    mf4, back, mapping = tmp_path / "run.mf4", tmp_path / "back.h5", tmp_path / "map.toml"
    assert main(["export", str(bench_run), "--to", str(mf4)]) == 0
    mapping.write_text('[channels.clamp_state]\nsource = "can_clutch.clamp_state"\nunit = "1"\n')
    assert main(["import", str(mf4), "--mapping", str(mapping), "--dt", "0.01", "--out", str(back)]) == 0
    run, source = load_run(back), load_run(bench_run)
    assert run.attrs["units"]["clamp_state"] == "1" and {0.0, 1.0} <= set(run["clamp_state"].dropna())
    rows = min(len(run), len(source))
    np.testing.assert_array_equal(run["T_air"].to_numpy()[:rows], source["T_air"].to_numpy()[:rows])


def test_mf4_of_some_channels_a_time_range_on_one_raster(bench_run, tmp_path, capsys):
    out = tmp_path / "part.mf4"
    assert main(["export", str(bench_run), "--to", str(out), "--channels", "T_air,engine_speed",
                 "--channels", "can_clutch.clamp_state", "--start", "2", "--stop", "8", "--raster", "0.1"]) == 0
    run = load_run(bench_run)
    mdf = MDF(out)
    try:
        names = {ch.name for group in mdf.groups for ch in group.channels}
        assert names == {"time", "T_air", "engine_speed", "can_clutch.time", "can_clutch.clamp_state"}
        speed, _ = _values(mdf, "engine_speed")
        clamp = mdf.get("can_clutch.clamp_state", raw=True)
        np.testing.assert_allclose(clamp.timestamps, np.arange(2.0, 8.0 + 1e-9, 0.1), atol=1e-9)
        assert clamp.samples.dtype.kind in "iu" and {0, 1} <= set(clamp.samples.tolist())  # held: no 0.5
        grid = run["time"].to_numpy()
        np.testing.assert_allclose(speed, np.interp(np.arange(2.0, 8.0 + 1e-9, 0.1), grid, run["engine_speed"]),
                                   atol=1e-6)
    finally:
        mdf.close()
    _one_line_exit_2(["export", str(bench_run), "--to", str(tmp_path / "x.mf4"), "--channels", "T_nothing"],
                     capsys, "--channels", "T_nothing")
    _one_line_exit_2(["export", str(bench_run), "--to", str(tmp_path / "x.mf4"), "--start", "5", "--stop", "1"],
                     capsys, "--start")
