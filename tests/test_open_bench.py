"""`RunRequest.bench` on hardware: a BENCH.toml is opened without the simulator (sim_bench is never imported)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# a run on a BENCH.toml whose devices cannot be reached: checks, plan, then the drivers fail to open (exit 2, the
# BENCH.toml key named)
OPEN_HARDWARE = """
import sys
from pathlib import Path
from benchlab.errors import InputError
from benchlab.runner.session import RunRequest, execute

try:
    execute(RunRequest("table1", Path(sys.argv[2]), bench=sys.argv[1], cycles=1, install_signals=False))
except InputError as exc:
    print("failed:", exc)
print("sim_bench imported:", sorted(m for m in sys.modules if m == "sim_bench" or m.startswith("sim_bench.")))
"""


def test_a_hardware_bench_is_opened_without_the_simulator(tmp_path):
    bench = tmp_path / "BENCH.toml"
    text = (ROOT / "examples" / "bench.toml").read_text()
    for device in ("/dev/ttyUSB0", "/dev/ttyACM0"):
        assert device in text
        text = text.replace(device, str(tmp_path / "no-such-port"))
    bench.write_text(text.replace('interface = "socketcan"', 'interface = "virtual"'))
    out = subprocess.run([sys.executable, "-c", OPEN_HARDWARE, str(bench), str(tmp_path / "run.h5")],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert "[instrument] url: " in out.stdout and "no-such-port' did not open" in out.stdout, out.stdout  # that far
    assert "sim_bench imported: []" in out.stdout, out.stdout
