"""The live view beside a real run: `benchlab run table1 --bench sim --watch` in a subprocess.

(a) The JSON updates follow the run as it is written (rows and bench time grow; the page's buckets, kept the
way watch.js keeps them, equal the min/max of the finished file), the watcher holds the run file read-only,
and the run's /aligned and events are identical to the same run without a watcher.
(b) Debian's headless Chromium opens the page and shows the run arriving: the sample count grows, the plots are
drawn, two screenshots differ. Skipped, saying why, where /usr/bin/chromium is absent (.ci/run installs it).
"""

from __future__ import annotations

import base64
import io
import json
import os
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import h5py
import numpy as np
import pytest

import headless_chromium
from benchlab.watch.decimate import minmax

DEADLINE_S = 600.0  # bounds every wait below; nothing asserts how long anything took


def _start_run(out: Path, seed: int, duration_s: int, watch: bool, realtime: float = 1000.0) -> subprocess.Popen:
    """The simulated run; watched, at `realtime` x real time (`--watch` alone would pace it at 1x)."""
    cmd = [sys.executable, "-m", "benchlab.cli", "run", "table1", "--bench", "sim", "--seed", str(seed),
           "--duration", str(duration_s), "--out", str(out), "--quiet"]
    cmd += ["--watch", "--port", "0", "--realtime", f"{realtime:g}"] if watch else []
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _url(proc: subprocess.Popen) -> str:
    line = proc.stderr.readline()
    assert line.startswith("live view  http://127.0.0.1:"), line
    return line.split()[-1]


def _get_json(url: str) -> dict | None:
    """The answer, or None when nobody answers (not started yet, or the run has ended and its watcher with it)."""
    try:
        with urllib.request.urlopen(url, timeout=30) as reply:
            return json.loads(reply.read())
    except (urllib.error.URLError, ConnectionError):
        return None


def _watcher_pid(run_pid: int) -> int | None:
    children = Path(f"/proc/{run_pid}/task/{run_pid}/children").read_text().split()
    for pid in children:
        if b"benchlab.watch" in Path(f"/proc/{pid}/cmdline").read_bytes():
            return int(pid)
    return None


def _access_modes(pid: int, path: Path) -> list[int]:
    """O_ACCMODE of every descriptor of `pid` open on the run file (or on a replaced version of it)."""
    modes = []
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
            flags = next(line for line in Path(f"/proc/{pid}/fdinfo/{fd}").read_text().splitlines()
                         if line.startswith("flags:"))
        except (FileNotFoundError, StopIteration):
            continue
        if target.removesuffix(" (deleted)") == str(path):
            modes.append(int(flags.split()[1], 8) & os.O_ACCMODE)
    return modes


class _Page:
    """The buckets a page holds, kept as watch.js keeps them (overwrite from the first one sent, drop before span)."""

    def __init__(self) -> None:
        self.level, self.first, self.min, self.max = None, 0, None, None

    def query(self) -> str:
        have = self.first + (self.min.shape[1] if self.min is not None else 0)
        return "width=600&span=0" + (f"&level={self.level}&have={have}" if self.level is not None else "")

    def apply(self, series: dict) -> None:
        mins = np.vstack([np.frombuffer(base64.b64decode(m), "<f4") for m in series["min"]])
        maxs = np.vstack([np.frombuffer(base64.b64decode(m), "<f4") for m in series["max"]])
        held = self.min.shape[1] if self.min is not None else 0
        if series["level"] != self.level or not self.first <= series["first"] <= self.first + held:
            self.level, self.first, self.min, self.max = series["level"], series["first"], mins, maxs
            return
        at = series["first"] - self.first
        self.min = np.hstack([self.min[:, :at], mins])
        self.max = np.hstack([self.max[:, :at], maxs])


def test_json_updates_follow_a_simulated_run_read_only_and_the_run_is_as_without_watcher(tmp_path):
    watched, plain = tmp_path / "watched.h5", tmp_path / "plain.h5"
    proc = _start_run(watched, seed=5, duration_s=900, watch=True)  # long enough to be seen growing
    page, seen, modes, last_status = _Page(), [], [], None
    try:
        url = _url(proc)
        deadline = time.monotonic() + DEADLINE_S
        while proc.poll() is None and time.monotonic() < deadline:
            answer = _get_json(url + "api/update?" + page.query())
            if answer is None:
                continue
            status = answer["status"]
            if status["status"] == "running" and status["rows"] > 0:
                seen.append((status["rows"], status["t_data"]))
                page.apply(answer["series"])
                last_status = status
                watcher = _watcher_pid(proc.pid)
                if watcher is not None:
                    modes += _access_modes(watcher, watched.resolve())
            time.sleep(0.05)
        out, err = proc.communicate(timeout=DEADLINE_S)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "run complete" in out
    rows = [r for r, _ in seen]
    times = [t for _, t in seen]
    assert len(set(rows)) >= 2, "the page saw the run grow at least once while it ran"
    assert rows == sorted(rows) and times == sorted(times)
    assert modes and set(modes) == {os.O_RDONLY}  # the watcher holds the run file read-only, nothing else
    assert _get_json(url + "api/update") is None  # the watcher ended with the run
    assert last_status["channels"][0]["unit"] and last_status["step"]["steps"] > 0
    with h5py.File(watched, "r") as f:
        names = [n for n in f["aligned"] if n != "time"]
        assert [c["name"] for c in last_status["channels"]] == names
        block = np.vstack([f["aligned"][n][:] for n in names])
    complete = last_status["rows"] >> page.level  # buckets whose rows had all arrived when last asked
    want_min, want_max = minmax(block, 1 << page.level)
    np.testing.assert_array_equal(page.min[:, :complete - page.first], want_min[:, page.first:complete])
    np.testing.assert_array_equal(page.max[:, :complete - page.first], want_max[:, page.first:complete])

    proc = _start_run(plain, seed=5, duration_s=900, watch=False)
    proc.communicate(timeout=DEADLINE_S)
    assert proc.returncode == 0
    with h5py.File(watched, "r") as a, h5py.File(plain, "r") as b:
        assert list(a["aligned"]) == list(b["aligned"])
        for name in a["aligned"]:
            np.testing.assert_array_equal(a["aligned"][name][:], b["aligned"][name][:], err_msg=name)
        for name in ("time", "kind", "detail"):
            np.testing.assert_array_equal(a["events"][name][:], b["events"][name][:], err_msg=name)


def _wait(condition, what: str, proc: subprocess.Popen):
    deadline = time.monotonic() + DEADLINE_S
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        assert proc.poll() is None, f"the run ended before {what}"
        time.sleep(0.2)
    raise AssertionError(f"{what}: not within {DEADLINE_S} s")


ROWS = "Number((document.body && document.body.dataset.rows) || 0)"
# drawn pixels (not transparent) in the temperature plot's canvas
INKED = """(() => { const c = document.querySelector('canvas[data-unit="degC"]'); if (!c) return 0;
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data; let n = 0;
  for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++; return n; })()"""


@pytest.mark.skipif(headless_chromium.available() is not None, reason=str(headless_chromium.available()))
def test_headless_chromium_shows_the_run_arriving(tmp_path):
    from PIL import Image

    out = tmp_path / "run.h5"
    # paced at 50x real time, long enough that the page sees it grow on a loaded core; the test stops it once it
    # has seen enough
    proc = _start_run(out, seed=2, duration_s=14400, watch=True, realtime=50.0)
    browser = None
    try:
        url = _url(proc)
        browser = headless_chromium.Chromium()
        browser.navigate(url)
        rows1 = _wait(lambda: browser.evaluate(ROWS), "the page showed samples", proc)
        _wait(lambda: browser.evaluate(INKED) > 0, "the page drew the temperatures", proc)
        first = browser.screenshot(tmp_path / "first.png")
        rows2 = _wait(lambda: (lambda r: r if r > rows1 else 0)(browser.evaluate(ROWS)), "more samples", proc)
        second = browser.screenshot(tmp_path / "second.png")
        badge = browser.evaluate("document.getElementById('badge').textContent")
        step = browser.evaluate("document.getElementById('step').textContent")
        events = browser.evaluate("Number(document.getElementById('event-count').textContent)")
        inked = browser.evaluate(INKED)
    finally:
        if browser is not None:
            browser.close()
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)  # enough seen: the run stops (exit 130) and its watcher with it
        proc.communicate(timeout=DEADLINE_S)
    assert rows2 > rows1 > 0
    assert badge == "running" and step.startswith("cycle ") and events > 0 and inked > 1000
    assert first != second
    for png in (first, second):
        image = Image.open(io.BytesIO(png)).convert("RGB")
        colours = image.getcolors(maxcolors=1 << 20)
        assert image.size[0] >= 1000 and len(colours) > 50  # not a blank page: text, panels and coloured curves
