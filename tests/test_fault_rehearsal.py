"""Fault rehearsal from the command line: `benchlab run … --bench sim --fault KIND@SECONDS[:key=value,…]`.

Every kind `sim_bench.faults.KINDS` knows can be given; what is wrong with a spec is refused at parse time
(exit 2, one line); the faults are recorded in the run file and take effect (their events are in /events).
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import h5py
import pytest

from benchlab.cli import main
from sim_bench.faults import KINDS, Fault, parse_fault

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE_BENCH = ROOT / "examples" / "bench.toml"
#: A value each option reads, so that every kind can be written with all its keys.
SAMPLE = {"value": "2", "duration_s": "5", "target": "load"}


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's usage errors
        code = exc.code
    return code, capsys.readouterr().err


def _events(path: Path) -> list[tuple[float, str, str]]:
    with h5py.File(path, "r") as f:
        g = f["events"]
        return [(float(t), k.decode(), d.decode()) for t, k, d in zip(g["time"][:], g["kind"][:], g["detail"][:])]


def test_the_issue_examples_parse_to_the_faults_the_simulated_bench_takes():
    assert parse_fault("instrument_disconnect@300") == Fault(300.0, "instrument_disconnect")
    assert parse_fault("air_heater@300:value=15000") == Fault(300.0, "air_heater", 15000.0)
    assert parse_fault("stuck_clutch@3.5:value=70,duration_s=25") == Fault(3.5, "stuck_clutch", 70.0, 25.0)
    assert parse_fault("controller_silent@0:target=clutch") == Fault(0.0, "controller_silent", target="clutch")
    assert parse_fault("instrument_error@10:value=-222,target=Data out of range") == \
        Fault(10.0, "instrument_error", -222.0, target="Data out of range")


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_every_kind_of_the_registry_can_be_given_with_each_of_its_keys(kind):
    options = KINDS[kind].options
    sample = {**SAMPLE, "target": "Self-test failed"} if kind == "instrument_error" else SAMPLE
    spec = f"{kind}@12.5" + (":" + ",".join(f"{k}={sample[k]}" for k in options) if options else "")
    fault = parse_fault(spec)
    assert fault.kind == kind and fault.at_s == 12.5
    assert {k: getattr(fault, k) for k in options} == {k: options[k].read(sample[k]) for k in options}
    assert all(getattr(fault, k) == getattr(Fault(0.0, kind), k) for k in ("value", "duration_s", "target")
               if k not in options)  # a key the kind does not read stays at its default


@pytest.mark.parametrize("spec, says", [
    ("no_such_fault@3", "unknown fault kind 'no_such_fault'"),
    ("air_heater", "no '@SECONDS'"),
    ("air_heater@-1", "a time in [0, 604800] s"),
    ("air_heater@nan", "a time in"),
    ("air_heater@inf", "a time in"),
    ("air_heater@1e12", "a time in"),
    ("air_heater@soon", "a time in"),
    ("air_heater@3:watts=15000", "air_heater takes value, got 'watts'"),
    ("instrument_disconnect@3:value=1", "takes no keys"),
    ("air_heater@3:value=hot", "a number in [0, 1e+06], got 'hot'"),
    ("air_heater@3:value=nan", "a number in"),
    ("air_heater@3:value=-5", "a number in"),
    ("air_heater@3:value", "key=value"),
    ("air_heater@3:value=1,value=2", "key=value"),
    ("radio_silence@3", "radio_silence needs duration_s="),
    ("radio_silence@3:duration_s=inf", "a number in"),
    ("stuck_clutch@3:duration_s=5", "stuck_clutch needs value="),
    ("controller_silent@3:target=brake", "one of drive, clutch, load, got 'brake'"),
    ("controller_fault@3:value=2.5", "an integer in [1, 255]"),
    ("instrument_error@3:target=say \"hi\"", "without quotes"),
])
def test_a_bad_fault_is_refused_at_parse_time(spec, says, tmp_path, capsys):
    out = tmp_path / "r.h5"
    code, err = _cli(["run", "table1", "--bench", "sim", "--fault", spec, "--out", str(out)], capsys)
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "--fault" in err and says in err and "Traceback" not in err, err
    assert not out.exists()


def test_faults_are_for_the_simulated_bench_only(tmp_path, capsys):
    out = tmp_path / "r.h5"
    code, err = _cli(["run", "table1", "--bench", str(EXAMPLE_BENCH), "--fault", "instrument_disconnect@300",
                      "--out", str(out)], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--fault" in err and "--bench sim" in err, err
    assert not out.exists()
    code, err = _cli(["run", "--resume", str(out), "--bench", "sim", "--fault", "instrument_disconnect@300"], capsys)
    assert code == 2 and "--fault" in err and "new run" in err, err


def test_faults_take_effect_and_are_recorded(tmp_path, capsys):
    """An instrument error and corrupt node frames, from the command line: their events, with the counts."""
    out = tmp_path / "faults.h5"
    code = main(["run", "table1", "--cycles", "1", "--bench", "sim", "--out", str(out), "--quiet",
                 "--fault", "instrument_error@20:value=-222,target=Data out of range",
                 "--fault", "corrupt_node_frames@40:value=25"])
    assert code == 0, capsys.readouterr().err
    with h5py.File(out, "r") as f:
        recorded = [Fault(**row) for row in json.loads(f.attrs["sim_faults"])]
    assert recorded == [Fault(20.0, "instrument_error", -222.0, target="Data out of range"),
                        Fault(40.0, "corrupt_node_frames", 25.0)]
    events = _events(out)
    errors = [(t, d) for t, k, d in events if k == "instrument_error"]
    assert len(errors) == 1 and errors[0][1] == "-222,Data out of range" and 20.0 <= errors[0][0] < 21.0
    frame_errors = [(t, d) for t, k, d in events if k == "frame_errors"]
    assert frame_errors and all(40.0 <= t < 43.0 for t, _ in frame_errors)  # counted per second, not per frame
    counts = [re.search(r"crc_errors (\d+), malformed (\d+), resyncs (\d+)", d) for _, d in frame_errors]
    assert all(counts), frame_errors
    assert sum(int(m.group(1)) for m in counts) == 25 and sum(int(m.group(2)) for m in counts) == 0
    _assert_dropouts_pair_up(events)


def _assert_dropouts_pair_up(events: list[tuple[float, str, str]]) -> None:
    """Every dropout_end follows one dropout_start (at most the last start is still open)."""
    kinds = [k for _, k, _ in events if k in ("dropout_start", "dropout_end")]
    assert kinds and all(k == ("dropout_start" if i % 2 == 0 else "dropout_end") for i, k in enumerate(kinds)), kinds


def test_the_readme_rehearsal_runs_as_it_says(tmp_path, capsys, monkeypatch):
    """The command of the README's "Rehearsing faults" section, run as printed: the interlock and the counts."""
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Rehearsing faults", 1)[1].split("\n## ", 1)[0]
    command = re.search(r"```sh\n(.*?)```", section, re.S).group(1).replace("\\\n", " ")
    argv = shlex.split(command)
    assert argv[0] == "benchlab" and "--fault" in argv
    monkeypatch.chdir(tmp_path)
    code = main(argv[1:] + ["--quiet"])
    assert code == 0, capsys.readouterr().err
    out = tmp_path / argv[argv.index("--out") + 1]
    with h5py.File(out, "r") as f:
        assert [row["kind"] for row in json.loads(f.attrs["sim_faults"])] == \
            ["air_heater", "air_heater", "corrupt_node_frames"]
    events = _events(out)
    trips = [(t, d) for t, k, d in events if k == "interlock"]
    assert trips and trips[0][1].startswith("air_over_temperature") and 20.0 < trips[0][0] < 45.0
    assert "interlock_cleared" in [k for _, k, _ in events]
    assert any("crc_errors 25" in d for _, k, d in events if k == "frame_errors")
    _assert_dropouts_pair_up(events)


def test_a_silence_under_way_is_extended_by_a_later_one_never_shortened():
    """The emulated node: a random 0.2 s drop-out 5 s into a rehearsed 30 s silence used to end the silence at
    5.2 s (its end overwritten); the frames of the whole 30 s stay lost, and a later, longer one extends it."""
    from sim_bench.emulators.clutch_node import ClutchNodeEmulator

    now = [0.0]
    node = ClutchNodeEmulator(clock=lambda: now[0], period_s=0.05)
    node.radio_silence(30.0)
    for t, silence in ((5.0, 0.2), (20.0, 1.0), (29.0, 6.0)):
        now[0] = t
        node.read_available()
        node.radio_silence(silence)
    now[0] = 34.9
    assert node.read_available() == b"" and node.frames_sent == 0
    now[0] = 40.0
    assert node.read_available() and node.frames_sent == round((40.0 - 35.0) / 0.05) + 1


def _node_frames_in(path: Path, start: float, end: float) -> int:
    """Node frames the run file holds stamped in [start, end) (its /raw/node stream, as the PC received them)."""
    with h5py.File(path, "r") as f:
        t = f["raw/node/time"][:]
    return int(((t >= start) & (t < end)).sum())


@pytest.mark.parametrize("start, duration", [(127.0, 30.0), (40.0, 4.0)])
def test_a_radio_silence_lasts_its_duration_on_the_bench(tmp_path, start, duration):
    """The issue's rehearsal `radio_silence@127:duration_s=30` held 594 node frames in its 30 s: random drop-outs
    (here one a minute) cut it short. On the bench it now lasts its length: no frame in it, frames up to it and
    right after it at the node's rate (20 Hz)."""
    from benchlab.runner.session import RunRequest, execute
    from sim_bench.bench import SimulatedBench
    from sim_bench.virtual_run import SensorConfig

    out = tmp_path / "silence.h5"
    bench = SimulatedBench(faults=[Fault(start, "radio_silence", duration_s=duration)],
                           options={"sensors": SensorConfig(dropouts_per_hour=60.0, dropout_mean_s=0.5)})
    code, _ = execute(RunRequest("table1", out, bench=bench, duration_s=start + duration + 30.0,
                                 install_signals=False))
    assert code == 0
    with h5py.File(out, "r") as f:
        starts = [float(t) for t, k in zip(f["events/time"][:], f["events/kind"][:]) if k == b"dropout_start"]
    if duration >= 10:  # the case of the issue: a random drop-out started inside the silence
        assert any(start < t < start + duration for t in starts), starts
    rate = 20.0
    assert _node_frames_in(out, start + 0.3, start + duration) == 0  # 0.3 s: frames sent before, received late
    before, after = (_node_frames_in(out, start - 5.0, start), _node_frames_in(out, start + duration + 1.0,
                                                                                 start + duration + 6.0))
    assert after >= 0.8 * 5.0 * rate and before >= 0.8 * 5.0 * rate, (before, after)
