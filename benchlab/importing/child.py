"""A reader of a stranger's file (asammdf, python-can) run in a child process with a memory and a CPU limit.

The readers are native code and trust what a file declares: a block claiming a terabyte crashed asammdf's extension
(SIGSEGV, no message), a compression bomb took gigabytes before any refusal. In a forked child (RLIMIT_AS: the
memory the command holds plus the reader's budget; RLIMIT_CPU) a crash, a memory request beyond the budget or a
reader that does not end is one line naming the file (InputError, exit 2); the command itself never runs out.
"""

from __future__ import annotations

import faulthandler
import os
import pickle
import resource
import signal
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from benchlab.bounds import (INFLATION_FLOOR_BYTES, MAX_INFLATED_BYTES, MAX_INFLATION, READER_CPU_FLOOR_S,
                             READER_CPU_S_PER_MB, READER_MEMORY_FLOOR, READER_MEMORY_PER_BYTE)
from benchlab.errors import InputError

T = TypeVar("T")


@dataclass(frozen=True)
class ReaderLimits:
    """What a reader may use: address space beyond the command's (bytes) and CPU time (s)."""

    memory_bytes: int
    cpu_s: float

    @classmethod
    def for_input(cls, path: Path, inflated_bytes: int = 0, blocks: str = "compressed blocks",
                  ratio: int = MAX_INFLATION) -> "ReaderLimits":
        """The limits for reading `path`, whose `blocks` declare they inflate to `inflated_bytes` (bounds.py says
        how much); InputError before anything is inflated where that is more than `ratio` times the file's size
        (INFLATION_FLOOR_BYTES at least) or MAX_INFLATED_BYTES."""
        size = path.stat().st_size
        most = min(MAX_INFLATED_BYTES, max(ratio * size, INFLATION_FLOOR_BYTES))
        if inflated_bytes > most:
            raise InputError(path, blocks, f"at most {most:,} bytes uncompressed ({ratio} times the file's "
                                           f"size, {INFLATION_FLOOR_BYTES >> 20} MiB at least, "
                                           f"{MAX_INFLATED_BYTES >> 30} GiB at most), they declare "
                                           f"{inflated_bytes:,}: a compression bomb or a damaged file")
        size += inflated_bytes
        return cls(READER_MEMORY_FLOOR + READER_MEMORY_PER_BYTE * size,
                   READER_CPU_FLOOR_S + READER_CPU_S_PER_MB * size / 1e6)


def _address_space() -> int | None:
    """This process's address space now, bytes (Linux: /proc/self/statm, first field in pages); None elsewhere."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[0]) * resource.getpagesize()
    except OSError:
        return None


def _in_child(write_fd: int, limits: ReaderLimits, function: Callable[..., Any], args: tuple[Any, ...]) -> None:
    """The child's side: limits set, `function(*args)` run, ("ok", result), ("input", error fields) or ("failed",
    text) sent on `write_fd`, and the process ended without running the parent's exit handlers."""
    code = 0
    faulthandler.disable()  # a crash is the parent's one line, not a dump of the child's stack
    try:
        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        if (now := _address_space()) is not None:  # where the system cannot say, the CPU limit alone
            memory = now + limits.memory_bytes
            resource.setrlimit(resource.RLIMIT_AS, (memory if hard == resource.RLIM_INFINITY else min(memory, hard),
                                                    hard))
        cpu = int(limits.cpu_s) + 1
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))  # SIGXCPU at the soft limit, SIGKILL at the hard
        try:
            reply: tuple[Any, ...] = ("ok", function(*args))
        except InputError as exc:
            reply = ("input", exc.source, exc.field, exc.expected)
        except MemoryError:
            reply = ("memory",)
        except BaseException as exc:  # noqa: BLE001 - anything the reader raises is one line in the parent
            reply = ("failed", f"{type(exc).__name__}: {' '.join(str(exc).split())}"[:300])
        with os.fdopen(write_fd, "wb") as pipe:
            pickle.dump(reply, pipe, protocol=pickle.HIGHEST_PROTOCOL)
    except MemoryError:  # no memory left even to send the result
        code = 3
    except BaseException:  # noqa: BLE001 - the parent reads no reply and reports how the child ended
        code = 4
    os._exit(code)


def _received(read_fd: int) -> bytes:
    """Everything the child sends, until it closes the pipe (by ending)."""
    chunks = []
    with os.fdopen(read_fd, "rb") as pipe:
        while chunk := pipe.read(1 << 20):
            chunks.append(chunk)
    return b"".join(chunks)


def read_in_child(path: "str | os.PathLike[str]", what: str, limits: ReaderLimits,
                  function: Callable[..., T], *args: Any) -> T:
    """`function(*args)` (a reader of the file `path`, which is `what`, e.g. "an MDF file asammdf reads") in a
    forked child within `limits`; its result, or InputError naming the file where the reader crashed, needed more
    memory or CPU time than the limits give, or failed."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child (coverage does not follow a fork that ends by os._exit)
        os.close(read_fd)
        _in_child(write_fd, limits, function, args)
    os.close(write_fd)
    status = None
    try:
        data = _received(read_fd)
        _, status, _ = os.wait4(pid, 0)
    finally:
        if status is None:  # interrupted (Ctrl-C) while the child reads: it ends with the command
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
    return _result(Path(path), what, limits, data, status)


def _result(path: Path, what: str, limits: ReaderLimits, data: bytes, status: int) -> Any:
    """The child's reply as the result, or InputError saying how the reader ended."""
    budget = f"{limits.memory_bytes / 2**20:.0f} MB of memory and {limits.cpu_s:.0f} s of CPU"
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        if sig in (signal.SIGXCPU, signal.SIGKILL):
            raise InputError(path, "file", f"{what} within {budget} (the reader ran out of CPU time: a damaged "
                                           "or hostile file)")
        raise InputError(path, "file", f"{what} (the reader crashed on it: {signal.Signals(sig).name})")
    reply = pickle.loads(data) if data else ("memory",) if os.WEXITSTATUS(status) == 3 else ("failed", "no reply")
    if reply[0] == "ok":
        return reply[1]
    if reply[0] == "input":
        raise InputError(*reply[1:])
    if reply[0] == "memory":
        raise InputError(path, "file", f"{what} within {budget} (the reader asked for more memory: a file that "
                                       "inflates beyond what it declares)")
    raise InputError(path, "file", f"{what} ({reply[1]})")
