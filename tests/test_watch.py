"""The live view's parts: min/max pyramid, following a run file as RunWriter writes it, HTTP server, CLI.

A run being written, its growth and its close (both os.replace), another run under the same name; what one
update reads (only what is new); the watcher never writes; bad input and Ctrl-C.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import signal
import subprocess
import sys
import threading
import urllib.error
import urllib.request
from contextlib import contextmanager

import h5py
import numpy as np
import pandas as pd
import pytest

from benchlab.acquire import AlignedSource, Layout, RunWriter, StreamSpec
from benchlab.cli import main
from benchlab.runfile import write_run
from benchlab.runfile import live as follow
from benchlab.watch.decimate import BASE_LEVEL, MinMaxPyramid, minmax
from benchlab.watch.live import LiveRun, Schedule, choose_level
from benchlab.watch.server import WatchServer, listen
from protocols.schedule import Condition, Step

from crashed import write_then_kill  # tests/crashed.py

LAYOUT = Layout(streams=(StreamSpec("s", (("a", "degC"), ("b", "rpm")), rate_hz=10.0, hold_s=0.15),),
                sources=(AlignedSource("T_air", "s", "a"), AlignedSource("engine_speed", "s", "b")),
                aligned_units={"T_air": "degC", "engine_speed": "rpm"})
STEPS = [Step("drive", 30.0, 1500.0, cycle=0), Step("open", 200.0, 800.0, cycle=0,
                                                    until=(Condition("T_flywheel", "<=", 60.0),), estimate_s=50.0)]


def _decode(text: str) -> np.ndarray:
    import base64

    return np.frombuffer(base64.b64decode(text), dtype="<f4")


def _reference(path, level):
    """Min/max per bucket straight from the file with h5py: what the pyramid must hold."""
    with h5py.File(path, "r") as f:
        block = np.vstack([f["aligned"][n][:] for n in f["aligned"] if n != "time"])
    return minmax(block, 1 << level)


# -- decimation -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pyramid_built_piece_by_piece_equals_min_max_of_all_rows(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5_000, 40_000))
    data = rng.normal(size=(3, n))
    data[rng.random(size=data.shape) < 0.05] = np.nan
    data[1, 1000:3000] = np.nan  # whole buckets without a measured sample stay NaN
    pyramid, rows = MinMaxPyramid(3), 0
    while rows < n:  # as the follower does: the base bucket still filling is passed again whole
        stop = min(n, rows + int(rng.integers(1, 2_000)))
        start = rows - rows % (1 << BASE_LEVEL)
        pyramid.ingest(start, data[:, start:stop])
        rows = stop
    for level in (BASE_LEVEL, BASE_LEVEL + 1, BASE_LEVEL + 4, 20):
        mins, maxs = pyramid.buckets(level, 0, 10**9)
        want_min, want_max = minmax(data, 1 << level)
        np.testing.assert_array_equal(mins, want_min)
        np.testing.assert_array_equal(maxs, want_max)
    assert np.isnan(pyramid.buckets(BASE_LEVEL, 10, 20)[0][1]).all()


def test_level_puts_the_span_on_at_most_one_bucket_per_pixel():
    for rows in (1, 999, 1000, 1001, 60_000, 3_600_000, 10**9):
        level = choose_level(rows, 1000)
        assert -(-rows // (1 << level)) <= 1000
        assert level == 0 or -(-rows // (1 << (level - 1))) > 1000


# -- following a run as it is written -------------------------------------------------------------------------
def _writer_options(path, planned_s=5.0):
    return {"protocol": "test", "attrs": {"created_utc": str(path)}, "planned_s": planned_s,
            "schedule": [s.as_dict() for s in STEPS], "state_fields": ("cycle", "next_step", "held")}


def _writer(path, planned_s=5.0):
    return RunWriter(path, LAYOUT, **_writer_options(path, planned_s))


def test_follows_the_writer_through_growth_and_close_reading_only_what_is_new(tmp_path, monkeypatch):
    path = tmp_path / "run.h5"
    writer = _writer(path)  # room for about 65 s: the run grows past it (rebuild, os.replace)
    live = LiveRun(path)
    reads: list[tuple[int, int]] = []
    original = follow.RunFileVersion.read_channels

    def recorded(self, start, stop):
        reads.append((start, stop))
        return original(self, start, stop)

    monkeypatch.setattr(follow.RunFileVersion, "read_channels", recorded)
    assert fcntl.fcntl(live.version.fd, fcntl.F_GETFL) & os.O_ACCMODE == os.O_RDONLY  # it cannot write
    inodes, have, level, seen_t = {live.version.inode}, 0, None, []
    writer.state.update(cycle=0, next_step=0, held=0)
    writer.event(0.0, "step_start", 0, "drive", step=0)
    for second in range(1, 101):
        for k in range(10):
            t = second - 1 + k / 10
            writer.add("s", t, (20.0 + t / 10, 1500.0 if k != 3 else np.nan))
        if second == 40:
            writer.event(39.5, "step_end", 0, "drive: time", step=0, reason="time")
            writer.state["next_step"] = 1
            writer.event(39.5, "step_start", 0, "open", step=1)
        if second == 60:
            writer.event(59.5, "interlock", 0, "stale_T_air: no valid reading for 5.2 s (hold)", step=1,
                         reason="stale_T_air")
            writer.state["held"] = 1
        if second == 70:
            writer.event(69.5, "interlock_cleared", 0, "stale_T_air")
            writer.state["held"] = 0
        writer.advance(float(second))
        before, n_reads = live.rows, len(reads)
        answer = live.update(width=400, level=level, have=have, events_from=0)
        status, series = answer["status"], answer["series"]
        inodes.add(live.version.inode)
        assert status["rows"] == writer.rows and status["generation"] == 0
        # the file: from the base bucket still filling on, the rows that arrived (not the whole run)
        assert reads[n_reads] == (before - before % (1 << BASE_LEVEL), writer.rows)
        if level == series["level"]:
            assert series["first"] == have - 1  # only the last bucket again and what is new
            if level < BASE_LEVEL:  # finer than the pyramid: read from the file, from that bucket on
                assert reads[-1] == ((have - 1) << level, writer.rows) and len(reads) == n_reads + 2
            else:
                assert len(reads) == n_reads + 1
        level, have = series["level"], series["first"] + series["count"]
        seen_t.append(status["t_data"])
        held = 60 <= second < 70
        assert status["held"] == held and list(status["interlocks"]) == (["stale_T_air"] if held else [])
    assert seen_t == sorted(seen_t) and len(set(seen_t)) == 100
    assert len(inodes) >= 2  # grew past its capacity: a new file under the same name, followed
    step = live.update()["status"]["step"]
    assert (step["index"], step["phase"], step["until"]) == (1, "open", "T_flywheel <= 60")
    assert [(e["kind"], e["step"], e["reason"]) for e in live.events] == [
        ("step_start", 0, ""), ("step_end", 0, "time"), ("step_start", 1, ""), ("interlock", 1, "stale_T_air"),
        ("interlock_cleared", -1, "")]
    assert step["elapsed_s"] == pytest.approx(100.0 - 39.5) and step["left_s"] == pytest.approx(200 - 60.5)
    writer.close("complete")  # compacted and compressed: read through h5py from now on
    answer = live.update(width=400, level=level, have=have)
    assert answer["status"]["status"] == "complete" and answer["status"]["rows"] == writer.rows
    assert isinstance(live.version.columns["T_air"], follow._H5Column)
    for lvl in (2, BASE_LEVEL, BASE_LEVEL + 3):
        series = live.series(lvl, 0)
        want_min, want_max = _reference(path, lvl)
        got_min = np.vstack([_decode(m) for m in series["min"]])
        got_max = np.vstack([_decode(m) for m in series["max"]])
        np.testing.assert_array_equal(got_min, want_min[:, :series["count"]])
        np.testing.assert_array_equal(got_max, want_max[:, :series["count"]])
    latest = live.status()["latest"]
    assert latest["T_air"]["value"] == pytest.approx(20.0 + 99.9 / 10)
    live.close()


def test_another_run_under_the_same_name_starts_again_and_a_deleted_file_keeps_what_was_read(tmp_path):
    path = tmp_path / "run.h5"
    calls = [("add", ("s", k / 10, (21.0, 900.0))) for k in range(300)] + [("advance", (30.0,))]
    rows = write_then_kill(path, LAYOUT, calls, **_writer_options(path, planned_s=100.0))  # a crashed run
    live = LiveRun(path)
    assert live.update()["status"]["rows"] == rows
    other = tmp_path / "other.h5"
    frame = pd.DataFrame({"time": np.arange(50) * 0.1, "T_air": np.full(50, 30.0)})
    write_run(other, frame, 0.1, protocol="imported")
    os.replace(other, path)
    status = live.update()["status"]
    assert (status["generation"], status["rows"], status["protocol"], status["dt"]) == (1, 50, "imported", 0.1)
    assert "another run" in status["problem"]
    path.unlink()
    status = live.update()["status"]
    assert status["rows"] == 50 and "cannot be read" in status["problem"]
    live.close()


def test_step_status_reads_the_runner_state():
    schedule = Schedule([*STEPS, Step("drive", 7.0, 900.0, cycle=1)])
    assert schedule.status({}, None, 5.0) is None and Schedule(()).status({"next_step": 0.0}, None, 1.0) is None
    assert (schedule.planned_s, schedule.cycles) == (30.0 + 50.0 + 7.0, 2)
    drive = schedule.status({"next_step": 0.0}, ("step_start", 1.0), 11.0)
    assert (drive["phase"], drive["left_s"], drive["run_left_s"]) == ("drive", 20.0, 20.0 + 50.0 + 7.0)
    waiting = schedule.status({"next_step": 1.0}, ("step_end", 31.0), 31.0)
    assert not waiting["started"] and waiting["left_s"] == 200.0 and waiting["run_left_s"] == 50.0 + 7.0
    assert schedule.status({"next_step": 3.0}, ("step_end", 90.0), 90.0)["done"]


# -- server -----------------------------------------------------------------------------------------------
@contextmanager
def serving(run_file, **options):
    """A WatchServer for the run file on a free port of 127.0.0.1, serving in a thread (options: WatchServer's)."""
    live = LiveRun(run_file)
    server = WatchServer(live, listen(0), **options)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.shutdown()
        server.server_close()
        live.close()


@pytest.fixture()
def served(run_file):
    with serving(run_file) as server:
        yield server


def _get(url, host=None):
    request = urllib.request.Request(url, headers={"Host": host} if host else {})
    try:
        with urllib.request.urlopen(request, timeout=30) as reply:
            return reply.status, reply.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def test_server_answers_page_and_updates_and_never_writes_the_file(served, run_file):
    before = (hashlib.sha256(run_file.read_bytes()).hexdigest(), os.stat(run_file).st_mtime_ns)
    assert served.server_address[0] == "127.0.0.1"
    rows = h5py.File(run_file, "r")["aligned/time"].shape[0]
    code, page = _get(served.url)
    code_js, script = _get(served.url + "watch.js")
    assert code == code_js == 200 and b'src="watch.js"' in page
    assert b"http:" not in page + script and b"https:" not in page + script  # nothing fetched from elsewhere
    have, level = 0, None
    for span in (0, 0, 600, 60, 0):
        query = f"width=700&span={span}&events=0" + (f"&level={level}&have={have}" if level is not None else "")
        code, body = _get(served.url + "api/update?" + query)
        answer = json.loads(body)
        assert code == 200 and answer["status"]["rows"] == rows and answer["status"]["status"] == "complete"
        series = answer["series"]
        assert series["count"] <= 701 and len(series["min"]) == len(answer["status"]["channels"])
        level, have = series["level"], series["first"] + series["count"]
    assert _get(served.url + "api/update?width=abc")[0] == 400
    assert _get(served.url + "nothing")[0] == 404
    assert _get(served.url, host="attacker.example:80")[0] == 403
    assert (hashlib.sha256(run_file.read_bytes()).hexdigest(), os.stat(run_file).st_mtime_ns) == before


# -- command line -----------------------------------------------------------------------------------------
def test_watch_refuses_what_is_not_a_run_and_a_port_in_use(tmp_path, run_file, capsys):
    text = tmp_path / "notes.txt"
    text.write_text("not hdf5")
    plain = tmp_path / "plain.h5"
    with h5py.File(plain, "w") as f:
        f["x"] = np.arange(3)
    for path, field in ((tmp_path / "missing.h5", "file"), (text, "file"), (plain, "schema")):
        assert main(["watch", str(path), "--port", "0"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and str(path) in err and f": {field}: " in err
    busy = listen(0)
    try:
        assert main(["watch", str(run_file), "--port", str(busy.getsockname()[1])]) == 2
    finally:
        busy.close()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--port" in err and "in use" in err
    assert main(["run", "table1", "--bench", "sim", "--out", str(tmp_path / "r.h5"), "--port", "0"]) == 2
    assert "--watch" in capsys.readouterr().err
    busy = listen(0)
    try:  # run --watch takes its port before anything moves
        out = tmp_path / "r.h5"
        assert main(["run", "table1", "--bench", "sim", "--out", str(out), "--watch", "--port",
                     str(busy.getsockname()[1])]) == 2
    finally:
        busy.close()
    assert "in use" in capsys.readouterr().err and not out.exists()
    with pytest.raises(SystemExit) as stop:
        main(["watch", str(run_file), "--port", "70000"])
    assert stop.value.code == 2 and "TCP port" in capsys.readouterr().err


def test_ctrl_c_ends_watch_with_130_and_one_line(run_file):
    proc = subprocess.Popen([sys.executable, "-m", "benchlab.cli", "watch", str(run_file), "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()
        assert line.startswith(f"watching {run_file} at http://127.0.0.1:"), line
        url = line.split(" at ")[1].split()[0]
        assert _get(url + "api/update")[0] == 200
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130
    assert err.strip() == "benchlab watch: interrupted" and "Traceback" not in err
