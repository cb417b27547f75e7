"""`benchlab watch RUN.h5 [--port N]`: follow a run in a web page on 127.0.0.1 while it is written."""

from __future__ import annotations

import argparse
import sys

from benchlab import cliargs
from benchlab.interrupts import interrupts_held

NAME = "watch"
HELP = "live view of a run file in a web page on 127.0.0.1 (follows a run while it is written; read-only)"
DEFAULT_PORT = 8765
port = cliargs.count("a TCP port (0: any free one)", 65535, minimum=0)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", metavar="RUN.h5", help="run file (one being written by `benchlab run`, or done)")
    parser.add_argument("--port", type=port, default=DEFAULT_PORT,
                        help=f"port on 127.0.0.1 (default {DEFAULT_PORT}; 0: any free one)")


def run(args: argparse.Namespace) -> int:
    """Serve until Ctrl-C (exit 130); a file that is not a run or a port in use is bad input (exit 2)."""
    with interrupts_held():  # the implementation's imports (see benchlab.cli): Ctrl-C meanwhile is exit 130
        from benchlab.watch.live import LiveRun
        from benchlab.watch.server import HOST, listen, serve

    live = LiveRun(args.run)
    try:
        sock = listen(args.port)
    except BaseException:
        live.close()
        raise
    print(f"watching {args.run} at http://{HOST}:{sock.getsockname()[1]}/ (Ctrl-C to stop)", file=sys.stderr,
          flush=True)
    serve(live, sock)
    return 0
