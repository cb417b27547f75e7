"""The watcher process that `benchlab run --watch` starts (launch.py): python -m benchlab.watch RUN.h5 FD.

Serves the live view of RUN.h5 on the listening socket FD it inherited, once the run has made the file, and
ends when its stdin closes (the run command has ended or died).
"""

from __future__ import annotations

import socket
import sys
import threading

from benchlab.errors import InputError
from benchlab.watch.live import LiveRun
from benchlab.watch.server import serve

WAIT_S = 0.2


def _stop_when_stdin_closes() -> threading.Event:
    stop = threading.Event()

    def read() -> None:
        sys.stdin.buffer.read()
        stop.set()

    threading.Thread(target=read, daemon=True).start()
    return stop


def main(argv: list[str]) -> int:
    path, fd = argv
    sock = socket.socket(fileno=int(fd))
    stop = _stop_when_stdin_closes()
    live = None
    while live is None and not stop.is_set():
        try:
            live = LiveRun(path)
        except InputError:  # not made yet (or still the previous file's start): look again
            stop.wait(WAIT_S)
    if live is None:
        return 0
    try:
        serve(live, sock, stop)
    except Exception as exc:  # noqa: BLE001 - one line, never a traceback over the run's own output
        print(f"benchlab watch: failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
