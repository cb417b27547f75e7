"""`benchlab run ... --watch`: the live view of the run being written, served by a process of its own.

The watcher runs in another process so that it can never hold up the acquisition (no shared interpreter lock,
the second core). Its socket is bound here, before the run starts, so a port in use is bad input before anything
moves, and the address is known at once. The watcher ends when this process closes its stdin, or dies.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from benchlab.watch.server import HOST, listen

STOP_TIMEOUT_S = 5.0


@contextmanager
def watching(path: Path, port: int) -> Iterator[str]:
    """Serve the live view of `path` (which the run is about to write) while the block runs; yields its URL."""
    sock = listen(port)  # InputError: port in use
    try:
        url = f"http://{HOST}:{sock.getsockname()[1]}/"
        proc = subprocess.Popen([sys.executable, "-m", "benchlab.watch", str(path), str(sock.fileno())],
                                pass_fds=(sock.fileno(),), stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                start_new_session=True)  # Ctrl-C is the run's to handle; it then stops the watcher
    finally:
        sock.close()  # the watcher holds its own copy
    try:
        yield url
    finally:
        assert proc.stdin is not None
        proc.stdin.close()
        try:
            proc.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
