"""The repository sends no reader outside itself: no tracked text file names a path beyond its root (a sibling
folder `shared` next to the checkout, the development machine's work folder; OUTSIDE below), and the contract it
cites lives in docs/contract.md."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: paths that leave the repository; spelled in pieces so that this file does not name them itself
OUTSIDE = re.compile(re.escape("../" + "shared") + "|" + re.escape("/" + "work/"))


def tracked_files(root: Path) -> list[Path]:
    """The files git tracks under `root`; every file but hidden folders and caches where it is not a checkout."""
    try:
        listed = subprocess.run(["git", "-C", str(root), "ls-files", "-z"], capture_output=True, check=True)
        return [root / name for name in listed.stdout.decode().split("\0") if name]
    except (OSError, subprocess.CalledProcessError):
        files = []
        for folder, dirs, names in os.walk(root):
            dirs[:] = [d for d in dirs if not d.startswith(".") and d != "__pycache__"]
            files += [Path(folder) / name for name in names]
        return files


def outside_references(root: Path) -> list[str]:
    """`file:line: text` for each line of a tracked text file that names a path outside the repository."""
    found = []
    for path in tracked_files(root):
        try:
            text = path.read_bytes()
        except (FileNotFoundError, IsADirectoryError):  # deleted in the work tree, or a submodule
            continue
        if b"\0" in text:  # binary: figures, HDF5, BLF
            continue
        for number, line in enumerate(text.decode("utf-8", errors="replace").splitlines(), start=1):
            if OUTSIDE.search(line):
                found.append(f"{path.relative_to(root)}:{number}: {line.strip()[:120]}")
    return found


def test_no_tracked_file_names_a_path_outside_the_repository():
    found = outside_references(ROOT)
    assert not found, "paths outside the repository:\n" + "\n".join(found)


def test_the_check_finds_such_a_path_and_names_file_and_line(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "page.md").write_text("first line\nsee `../" + "shared/spec/contract.md`\n")
    (tmp_path / "tool.py").write_text("DATA = '/" + "work/data'\n")
    (tmp_path / "figure.png").write_bytes(b"\x89PNG\0../" + b"shared")
    found = sorted(outside_references(tmp_path))  # not a checkout: every file but the hidden ones
    assert [f.split(": ")[0] for f in found] == ["docs/page.md:2", "tool.py:1"]


def test_the_contract_is_in_the_repository_with_numbered_sections():
    contract = (ROOT / "docs" / "contract.md").read_text()
    sections = re.findall(r"^## (\d+)\. ", contract, flags=re.MULTILINE)
    assert sections == [str(n) for n in range(1, len(sections) + 1)] and len(sections) >= 6
    for promised in ("benchlab-run/1", "benchlab-model/1", "not_identified", "unseen_gain_pct", "leads",
                     "summary.json", "plate_band_coverage", "eq11_rel_error", "cooldown_nrmse_pct"):
        assert promised in contract, promised
