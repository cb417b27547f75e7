"""Files from strangers (issue 44): compressed inputs that declare more than they hold, or hold more than they
declare, and readers that crash or never end. Each is refused in one line naming the file, exit 2, within bounded
memory (the command's peak, its reader child included, from getrusage) and without hanging. The hostile files are made
here, from files asammdf and python-can write, patched as a sender would."""

from __future__ import annotations

import ctypes
import os
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import can
import numpy as np
import pytest

from benchlab.errors import InputError
from benchlab.importing.canlog import BLF_CONTAINER, BLF_OBJECT, blf_inflated_size
from benchlab.importing.child import ReaderLimits, read_in_child
from benchlab.importing.mdf import BLOCK_HEADER, DZ_FIELDS, inflated_size

WAIT_S = 300.0  # upper bound on a command; reaching it is the hang this file tests against
#: Peak memory of `benchlab import` on an input under 10 MB (issue 44: "below 1 GB").
PEAK_BYTES = 1 << 30
GIB = 1 << 30


#: The command started from a small interpreter that waits for it and prints its exit code and peak: Linux starts a
#: forked process with its parent's resident size as its peak (the pages it shares count), so a command forked from
#: a test worker that ran the main job in-process (1.1 GB) would be charged the worker's size. RUSAGE_CHILDREN: the
#: largest peak of the command and the children it waited for (its reader child).
LAUNCH = ("import resource, subprocess, sys\n"
          "code = subprocess.call(sys.argv[1:], stdout=subprocess.DEVNULL)\n"
          "print(code, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024)")


def _cli(tmp_path: Path, *args: str) -> tuple[int, str, int]:
    """`benchlab ARGS` in a subprocess: exit code, stderr, and peak resident memory in bytes (its reader child
    included)."""
    err_path = tmp_path / "stderr.txt"
    with open(err_path, "w") as err:
        proc = subprocess.Popen([sys.executable, "-c", LAUNCH, sys.executable, "-m", "benchlab.cli", *args],
                                stdout=subprocess.PIPE, stderr=err, text=True, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=WAIT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)
        proc.wait()
        pytest.fail(f"benchlab {' '.join(args)} did not end within {WAIT_S:g} s")
    code, peak = (int(v) for v in out.split())
    return code, err_path.read_text(), peak


def _deflated_zeros(size: int) -> bytes:
    """`size` zero bytes deflated (a compression bomb's payload: about a thousandth of its size)."""
    packer, piece = zlib.compressobj(9), b"\0" * (1 << 24)
    parts = [packer.compress(piece) for _ in range(size // len(piece))]
    return b"".join(parts) + packer.compress(b"\0" * (size % len(piece))) + packer.flush()


def _small_mf4(path: Path) -> bytearray:
    """An MF4 asammdf writes: one channel group of the contract's clutch torque, 1000 samples."""
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    t = np.arange(1000) * 0.01
    mdf.append([Signal(np.zeros(1000), t, unit="Nm", name="clutch_torque")])
    mdf.save(path, overwrite=True, compression=2)
    mdf.close()
    return bytearray(path.read_bytes())


def _with_dz(data: bytearray, declared: int, payload: bytes) -> bytearray:
    """`data` (an MF4) with a ##DZ block (deflate) appended and the first data group's data pointing at it: it
    declares `declared` bytes and holds `payload`."""
    at = (len(data) + 7) // 8 * 8
    data = data + bytes(at - len(data))
    data += BLOCK_HEADER.pack(b"##DZ", BLOCK_HEADER.size + DZ_FIELDS.size + len(payload), 0)
    data += DZ_FIELDS.pack(b"DT", 0, 0, declared, len(payload)) + payload
    first_group = struct.unpack_from("<Q", data, 64 + BLOCK_HEADER.size)[0]  # the header block's first link
    struct.pack_into("<Q", data, first_group + BLOCK_HEADER.size + 2 * 8, at)  # the group's data link
    return data


def _one_line_refusal(code: int, err: str, path: Path) -> None:
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert str(path) in err, err


def test_an_mf4_claiming_a_terabyte_is_refused_from_its_block_headers(tmp_path):
    """The crash of issue 44: a ##DZ block claims 2^40 bytes. Refused before asammdf opens the file."""
    path = tmp_path / "claim.mf4"
    data = _small_mf4(path)
    path.write_bytes(_with_dz(data, 1 << 40, zlib.compress(bytes(80_000))))
    assert inflated_size(path) >= 1 << 40
    code, err, peak = _cli(tmp_path, "import", str(path), "--dt", "0.01", "--out", str(tmp_path / "run.h5"))
    _one_line_refusal(code, err, path)
    assert "compressed blocks (##DZ)" in err and "1,099,511,627,776" in err
    assert peak < PEAK_BYTES
    assert not (tmp_path / "run.h5").exists()


def test_an_mf4_inflating_beyond_what_it_declares_is_stopped_at_the_readers_memory_limit(tmp_path):
    """A deflate bomb that declares 16 kB and holds a GiB of zeros (1 MB on disk): the declared sizes pass, the
    reader (in its child process) is stopped at its memory limit, the command's peak stays far below the GiB."""
    path = tmp_path / "liar.mf4"
    path.write_bytes(_with_dz(_small_mf4(path), 16_000, _deflated_zeros(GIB)))
    assert path.stat().st_size < 10 << 20
    code, err, peak = _cli(tmp_path, "import", str(path), "--dt", "0.01", "--out", str(tmp_path / "run.h5"))
    _one_line_refusal(code, err, path)
    assert "memory" in err
    assert peak < PEAK_BYTES


def test_the_declared_sizes_of_a_bench_export_are_within_the_bound(tmp_path):
    """asammdf's own compressed groups (transposed deflate, as `benchlab export` writes) declare what they hold:
    the walk finds each ##DZ (through data lists) and the sum is their true size."""
    from asammdf import MDF, Signal

    n = 300_000
    t = np.arange(n) * 0.01
    mdf = MDF(version="4.10")
    mdf.append([Signal(np.sin(t / 30.0), t, unit="degC", name="T_air"),
                Signal(np.arange(n) % 3, t, unit="1", name="clutch_state")])
    path = tmp_path / "export.mf4"
    mdf.save(path, overwrite=True, compression=2)
    mdf.close()
    record = 8 + 8 + 8  # master, T_air (float64), clutch_state (int64)
    assert inflated_size(path) == n * record
    ReaderLimits.for_input(path, inflated_size(path))  # within the bound: no refusal


def _blf_head(tmp_path: Path) -> bytes:
    """The file header python-can's BLFWriter writes (an empty log)."""
    path = tmp_path / "head.blf"
    with can.BLFWriter(path):
        pass
    data = path.read_bytes()
    return data[:struct.unpack_from("<L", data, 4)[0]]


def _container(declared: int, payload: bytes) -> bytes:
    """A BLF log container (zlib) declaring `declared` bytes uncompressed, holding `payload`."""
    size = BLF_OBJECT.size + BLF_CONTAINER.size + len(payload)
    return (BLF_OBJECT.pack(b"LOBJ", BLF_OBJECT.size, 1, size, 10) + BLF_CONTAINER.pack(2, declared) + payload
            + bytes(size % 4))


@pytest.mark.parametrize("declared, inflated", [(256 << 20, 256 << 20), (128 << 10, 256 << 20)],
                         ids=["declared", "beyond-declared"])
def test_a_blf_bomb_is_refused_before_python_can_reads_it(tmp_path, declared, inflated):
    """A BLF log whose containers inflate to 256 MB from 250 kB: refused whether the containers say so (the bound
    on the declared size) or declare 128 kB (inflated a piece at a time and counted, never held whole)."""
    path = tmp_path / "bomb.blf"
    path.write_bytes(_blf_head(tmp_path) + _container(declared, _deflated_zeros(inflated)))
    with pytest.raises(InputError, match="compression bomb"):
        blf_inflated_size(path) if declared < inflated else ReaderLimits.for_input(path, blf_inflated_size(path))
    code, err, peak = _cli(tmp_path, "import", str(path), "--dt", "0.01", "--out", str(tmp_path / "run.h5"))
    _one_line_refusal(code, err, path)
    assert "compression bomb" in err
    assert peak < PEAK_BYTES


def test_a_blf_log_of_python_cans_writer_declares_what_it_holds(tmp_path):
    """The walk over a real log's containers sums to what python-can's writer wrote uncompressed."""
    path = tmp_path / "real.blf"
    with can.BLFWriter(path) as writer:
        for i in range(20_000):
            writer.on_message_received(can.Message(timestamp=1.7e9 + i * 0.001, arbitration_id=0x100 + i % 7,
                                                   data=bytes([i % 256] * 8)))
    assert blf_inflated_size(path) == 20_000 * 48  # each a CAN_MESSAGE object: base, v1 and message headers, 16 B each


def _segfault(path: Path) -> None:
    ctypes.string_at(0)  # reads address 0: SIGSEGV, as asammdf's extension did


def _spin(path: Path) -> None:
    while True:
        pass


def _allocate(path: Path) -> bytes:
    return bytes(4 * GIB)


def _refuse(path: Path) -> None:
    raise InputError(path, "channel x", "a number")


@pytest.mark.parametrize("reader, expected", [(_segfault, "crashed on it: SIGSEGV"), (_spin, "CPU time"),
                                              (_allocate, "more memory"), (_refuse, "channel x: a number")])
def test_a_reader_that_crashes_spins_or_allocates_is_one_line_naming_the_file(tmp_path, reader, expected):
    """The child process turns each way a reader can fail into InputError naming the file; the parent lives."""
    path = tmp_path / "input.mf4"
    path.write_bytes(b"MDF     4.10    ")
    limits = ReaderLimits(memory_bytes=256 << 20, cpu_s=1.0)
    with pytest.raises(InputError, match=expected) as raised:
        read_in_child(path, "an MDF file", limits, reader, path)
    assert str(raised.value).startswith(str(path))


def test_a_readers_result_comes_back_whole(tmp_path):
    path = tmp_path / "input.mf4"
    path.write_bytes(b"x")
    values = np.arange(3_000_000, dtype=np.float64)  # 24 MB: more than a pipe holds at once
    result = read_in_child(path, "a file", ReaderLimits(256 << 20, 60.0), lambda p, v: (p, v * 2), path, values)
    assert result[0] == path and np.array_equal(result[1], values * 2)


def _corrupt_deflate(path: Path) -> bytes:
    """An MF4 whose compressed block's deflate stream is overwritten part-way (isal's IsalError)."""
    data = _small_mf4(path)
    at = data.find(b"##DZ") + BLOCK_HEADER.size + DZ_FIELDS.size
    data[at + 2:at + 40] = b"\xff" * 38
    return bytes(data)


def _truncated_mf4(path: Path) -> bytes:
    return bytes(_small_mf4(path)[:3000])


@pytest.mark.parametrize("name, content", [
    ("year.log", lambda p: b"(99999999999999.000000) can0 123#0011223344556677\n"),
    ("long.log", lambda p: b"(1.0) can0 123#" + b"00" * 100_000 + b"\n"),
    ("huge.log", lambda p: b"(1" + b"0" * 400 + b".0) can0 123#00\n"),
    ("garbage.blf", lambda p: b"garbage garbage"),
    ("corrupt.mf4", _corrupt_deflate),
    ("truncated.mf4", _truncated_mf4),
], ids=["year-out-of-range", "long-log-line", "overflowing-stamp", "blf-parse-error", "isal-error", "truncated"])
def test_damaged_inputs_are_one_line_exit_2(tmp_path, refused, name, content):
    """What used to end in exit 1 with the library's exception (issue 44) is bad input naming the file."""
    path = tmp_path / name
    path.write_bytes(content(path))
    refused(["import", str(path), "--dt", "0.01", "--out", str(tmp_path / "run.h5")], str(path))
    assert not (tmp_path / "run.h5").exists()


def test_a_dbc_defining_a_frame_id_twice_is_refused_naming_the_dbc(tmp_path, refused):
    """Two messages of one frame id: a decoder keyed by id would keep one of them silently."""
    from drivers.can_signals import BENCH_DBC

    text = BENCH_DBC.read_text()
    first = text.index("\nBO_ ")
    end = text.index("\n\n", first + 1)
    block = text[first:end]
    frame_id, name = block.split()[1], block.split()[2].rstrip(":")
    twin = block.replace(f"BO_ {frame_id} {name}:", f"BO_ {frame_id} Twin{name}:").replace(" SG_ ", " SG_ Twin")
    dbc = tmp_path / "twice.dbc"
    dbc.write_text(text[:end] + twin + text[end:])
    log = tmp_path / "frames.asc"
    with can.ASCWriter(log) as writer:
        writer.on_message_received(can.Message(timestamp=1.0, arbitration_id=int(frame_id), data=bytes(8)))
    refused(["import", str(log), "--dbc", str(dbc), "--dt", "0.01", "--out", str(tmp_path / "run.h5")],
            str(dbc), f"frame id {int(frame_id):#x}")


def test_two_recordings_530_years_apart_are_not_merged_as_one_run(tmp_path, refused):
    """Each input holds the channel: the second used to be dropped silently (the first input gives a channel)."""
    from datetime import datetime, timezone

    from asammdf import MDF, Signal

    paths = []
    for year in (1980, 2510):
        mdf = MDF(version="4.10")
        mdf.append([Signal(np.zeros(100), np.arange(100) * 0.01, unit="Nm", name="clutch_torque")])
        mdf.header.start_time = datetime(year, 1, 1, tzinfo=timezone.utc)
        paths.append(tmp_path / f"rec{year}.mf4")
        mdf.save(paths[-1], overwrite=True)
        mdf.close()
    refused(["import", *map(str, paths), "--dt", "0.01", "--out", str(tmp_path / "run.h5")],
            "time stamps", "rec1980.mf4", "rec2510.mf4", "--offset")


@pytest.mark.parametrize("kind", ["##DG", "##CN"])
def test_an_mf4_whose_chain_of_blocks_loops_back_is_refused_before_asammdf_follows_it(tmp_path, refused, kind):
    """A data group (or channel) whose next link points at itself: asammdf followed it until its CPU limit
    (over a minute); the block walk finds the loop from the headers."""
    path = tmp_path / "loop.mf4"
    data = _small_mf4(path)
    group = struct.unpack_from("<Q", data, 64 + BLOCK_HEADER.size)[0]
    channel_group = struct.unpack_from("<Q", data, group + BLOCK_HEADER.size + 8)[0]
    channel = struct.unpack_from("<Q", data, channel_group + BLOCK_HEADER.size + 8)[0]
    at = group if kind == "##DG" else channel
    assert data[at:at + 4] == kind.encode()
    struct.pack_into("<Q", data, at + BLOCK_HEADER.size, at)  # its next link: itself
    path.write_bytes(data)
    refused(["import", str(path), "--dt", "0.01", "--out", str(tmp_path / "run.h5")], str(path),
            f"the {kind} block at byte {at}")
