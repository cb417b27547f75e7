"""Acquisition: the aligned grid's hold rules, the run-file layout, crash safety under SIGKILL, resume."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest

from benchlab.acquire import AlignedBuilder, AlignedSource, Layout, RunWriter, StreamSpec
from benchlab.runfile import ALIGNED_UNITS, load_run, read_progress

CHANNELS = {k: v for k, v in ALIGNED_UNITS.items() if k not in ("time", "T_engine")}


def _row(t: float) -> list[float]:
    """One reading at time t: every channel reads t, but clutch_state stays a state (0 or 1, as load_run checks)."""
    return [float(int(t) % 2) if k == "clutch_state" else t for k in CHANNELS]


def _layout(dt: float = 0.01, hold: float = 0.075) -> Layout:
    cols = tuple(CHANNELS.items())
    return Layout((StreamSpec("s", cols, 20.0, hold),), tuple(AlignedSource(k, "s", k) for k in CHANNELS),
                  CHANNELS, None, dt)


def test_reading_held_until_next_or_hold_limit_never_across_gaps():
    spec = StreamSpec("a", (("x", "1"),), 20.0, hold_s=0.075)
    layout = Layout((spec,), (AlignedSource("x", "a", "x"),), {"x": "1"}, None, 0.01)
    b = AlignedBuilder(layout)
    for t, v in ((0.0, 1.0), (0.05, 2.0), (0.10, np.nan), (0.15, 4.0), (0.60, 5.0)):
        b.add("a", t, (v,))
    x = b.finalise(71)["x"]
    assert np.all(x[0:5] == 1.0) and np.all(x[5:10] == 2.0)  # held until the next reading
    assert np.all(np.isnan(x[10:15]))  # a reading without a number is NaN on the grid
    assert np.all(x[15:23] == 4.0) and np.all(np.isnan(x[23:60]))  # held 75 ms, then nothing across the gap
    assert np.all(x[60:68] == 5.0) and np.all(np.isnan(x[68:71]))


def test_finalise_in_pieces_equals_in_one_go():
    spec = StreamSpec("a", (("x", "1"),), 20.0, hold_s=0.2)
    layout = Layout((spec,), (AlignedSource("x", "a", "x", 2.0),), {"x": "1"}, None, 0.01)
    rng = np.random.default_rng(1)
    times = np.sort(rng.uniform(0, 10, 150))
    one, pieces = AlignedBuilder(layout), AlignedBuilder(layout)
    for t in times:
        one.add("a", t, (t,))
    whole = one.finalise(1001)["x"]
    parts, i = [], 0
    for k in range(1, 1002, 37):
        while i < len(times) and times[i] <= (k - 1) * 0.01:
            pieces.add("a", times[i], (times[i],))
            i += 1
        parts.append(pieces.finalise(k)["x"])
    parts.append(pieces.finalise(1001)["x"])
    np.testing.assert_array_equal(np.concatenate(parts), whole)


def test_readings_in_blocks_give_the_same_file_as_one_by_one(tmp_path):
    """A driver may hand a stream's readings as blocks (times, rows), mixed with single readings and out of time
    order; raw streams and the aligned grid come out as if they had been added one by one."""
    rng = np.random.default_rng(4)
    times = np.sort(rng.uniform(0.0, 6.0, 400))
    times[rng.integers(0, 400, 20)] -= 0.03  # a few arrive late
    rows = np.array([_row(t) for t in times])
    rows[rng.integers(0, 400, 10), 2] = np.nan
    cuts = np.sort(rng.choice(np.arange(1, 400), 60, replace=False))
    for name, blocks in (("one.h5", False), ("blocks.h5", True)):
        w = RunWriter(tmp_path / name, _layout(), protocol="table1", planned_s=6.0)
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, 400]):
            if blocks and b - a > 1:
                w.add("s", times[a:b], rows[a:b])
            else:
                for t, row in zip(times[a:b], rows[a:b]):
                    w.add("s", float(t), tuple(row))
            w.advance(float(times[b - 1]) - 0.05)
        w.close("complete")
    with h5py.File(tmp_path / "one.h5", "r") as one, h5py.File(tmp_path / "blocks.h5", "r") as blocks:
        for group in ("aligned", "raw/s"):
            for name in one[group]:
                np.testing.assert_array_equal(blocks[group][name][:], one[group][name][:], err_msg=f"{group}/{name}")


def test_run_file_layout_units_status_and_events(tmp_path):
    path = tmp_path / "run.h5"
    w = RunWriter(path, _layout(), protocol="table1", attrs={"seed": 3}, planned_s=2.0,
                  schedule=[{"phase": "open", "duration_s": 1.0}], schedule_units={"duration_s": "s"},
                  state_fields=("cycle",))
    t = 0.0
    while t < 5.0:  # beyond the planned capacity: the file grows
        t = round(t + 0.05, 10)
        w.add("s", t, _row(t))
        w.advance(t)
    w.event(1.0, "cycle_start", 0, "x")
    with h5py.File(path, "r") as f:
        assert f.attrs["status"] == "running"
    w.close("complete")
    run = load_run(path)
    assert run.attrs["status"] == "complete" and run.attrs["protocol"] == "table1"
    assert run["time"].iloc[-1] == pytest.approx(5.0)
    with h5py.File(path, "r") as f:
        missing = []
        f.visititems(lambda n, o: missing.append(n) if isinstance(o, h5py.Dataset) and "units" not in o.attrs else None)
        assert missing == []
        assert f["events/kind"][0] == b"cycle_start" and f.attrs["seed"] == 3
        assert json.loads(f["schedule"].attrs["steps_json"])[0]["phase"] == "open"
        assert not os.path.exists(str(path) + ".tmp")


def test_compact_file_holds_the_running_files_values_gzipped_and_shuffled(tmp_path):
    """Closing writes its own compressed chunks (two of them here, the second only partly used): HDF5's gzip and
    shuffle filters read back exactly the values the running file held, NaN included."""
    path = tmp_path / "run.h5"
    w = RunWriter(path, _layout(), protocol="table1", planned_s=700.0)
    t = 0.0
    while t < 700.0:
        t = round(t + 0.05, 10)
        w.add("s", t, _row(t) if int(t) % 7 else [np.nan] * len(CHANNELS))
        w.advance(t)
    w.flush(t)
    with h5py.File(path, "r") as f:
        rows = int(read_progress(f)["aligned_rows"])
        running = {name: f["aligned"][name][:rows] for name in f["aligned"]}
    w.close("complete")
    with h5py.File(path, "r") as f:
        for name, values in running.items():
            ds = f["aligned"][name]
            assert ds.compression == "gzip" and ds.shuffle and ds.chunks == (65536,), name
            np.testing.assert_array_equal(ds[:], values, err_msg=name)
    assert rows > 65536 and np.isnan(running["clutch_torque"]).any()


def test_a_reading_with_the_wrong_number_of_values_is_refused(tmp_path):
    w = RunWriter(tmp_path / "run.h5", _layout(), protocol="table1", planned_s=2.0)
    with pytest.raises(ValueError, match="values for a stream of"):
        w.add("s", 0.1, _row(0.1)[:-1])


# The writer is paced (0.2 ms a reading, 4 ms a second of run): unpaced, a fast machine wrote 10,000 s of run in the
# 1.1 s before the kill, and every channel reads t, so the temperatures passed the reader's 10,000 degC bound.
WRITER = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, {root!r})
    from tests.test_acquire import _layout, _row
    from benchlab.acquire import RunWriter
    w = RunWriter(sys.argv[1], _layout(), protocol="table1", planned_s=600.0, state_fields=("cycle",))
    t = 0.0
    while True:
        time.sleep(0.0002)
        t = round(t + 0.05, 10)
        w.add("s", t, _row(t))
        if w.advance(t):
            w.state["cycle"] = t
            if t > 2:
                print("go", flush=True)
""")


@pytest.mark.parametrize("delay", [0.0, 0.37, 1.1])
def test_sigkill_leaves_a_readable_file_missing_at_most_one_second(tmp_path, delay):
    path = tmp_path / "killed.h5"
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    proc = subprocess.Popen([sys.executable, "-c", WRITER.format(root=root), str(path)], stdout=subprocess.PIPE)
    assert proc.stdout.readline().strip() == b"go"
    time.sleep(delay)
    with h5py.File(path, "r") as f:  # progress as seen just before the kill
        before = read_progress(f)["t_data"]
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    run = load_run(path)  # readable by the contract's reader
    assert run.attrs["status"] == "running"
    with h5py.File(path, "r") as f:
        progress = read_progress(f)
    rows = int(progress["aligned_rows"])
    valid = run["engine_speed"].to_numpy()[:rows]
    assert np.all(np.isfinite(valid[5:]))  # everything up to the progress mark is there
    t_valid = run["time"].to_numpy()[rows - 1]
    assert progress["t_data"] >= before and t_valid == pytest.approx(progress["t_data"], abs=0.011)
    # resume: the valid part is kept, new data appended, file completes
    w = RunWriter.resume(path, _layout(), extra_s=2.0)
    t0 = t_valid
    for k in range(1, 21):
        w.add("s", t0 + 0.05 * k, _row(t0 + 0.05 * k))
        w.advance(t0 + 0.05 * k)
    w.close("complete")
    run2 = load_run(path)
    assert run2.attrs["status"] == "complete"
    assert run2["time"].iloc[-1] == pytest.approx(t0 + 1.0, abs=0.011)
    np.testing.assert_array_equal(run2["engine_speed"].to_numpy()[:rows], valid)


def test_truth_rows_go_into_the_file_as_handed_over_across_a_growth_a_close_and_a_resume(tmp_path):
    """The simulated bench's /truth as RunWriter writes it: rows handed over ahead of the file's capacity wait for it
    to grow, the running file holds them (NaN after the last written batch), the close cuts them at the grid's rows,
    and a resumed writer keeps them and adds its own."""
    from benchlab.acquire.writer import TRUTH_BATCH_ROWS
    from benchlab.runfile import load_truth

    path, units = tmp_path / "run.h5", {"T_a": "degC", "T_b": "degC"}
    states = np.column_stack([np.arange(14000) * 0.5, -np.arange(14000.0)])
    w = RunWriter(path, _layout(), protocol="table1", planned_s=2.0, truth_units=units)  # 6,221 rows at first
    handed = 0
    for second in range(1, 101):
        w.advance(float(second))
        while handed < (second + 20) * 100:  # the bench hands chunks over ahead of the grid, past the capacity too
            w.put_truth(handed, states[handed:handed + 1000])
            handed += 1000
    running = load_truth(path)  # as a killed run would leave it: the written rows, NaN after
    written = int(np.argmax(np.isnan(running["T_a"].to_numpy())))
    assert len(running) == w.rows == 10001 and w.rows - TRUTH_BATCH_ROWS - 3000 <= written < w.rows
    np.testing.assert_array_equal(running[["T_a", "T_b"]].to_numpy()[:written], states[:written])
    w.close("aborted")
    closed = load_truth(path)
    np.testing.assert_array_equal(closed[["T_a", "T_b"]].to_numpy(), states[:10001])
    np.testing.assert_array_equal(closed["time"].to_numpy(), load_run(path)["time"].to_numpy())
    with h5py.File(path, "r") as f:
        assert {k: f["truth"][k].attrs["units"] for k in f["truth"]} == {"time": "s", **units}
    w = RunWriter.resume(path, _layout(), extra_s=10.0, truth_units=units)
    w.put_truth(10001, states[10001:11001])
    w.advance(110.0)
    w.close()
    np.testing.assert_array_equal(load_truth(path)[["T_a", "T_b"]].to_numpy(), states[:11001])
