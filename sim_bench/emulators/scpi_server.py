"""A serial endpoint (registry.SerialEndpoint, e.g. ScpiInstrumentEmulator) served on 127.0.0.1 as a raw SCPI socket.

What a LAN instrument offers on port 5025, reachable as the VISA resource `TCPIP0::127.0.0.1::PORT::SOCKET` or the
pyserial URL `socket://127.0.0.1:PORT`. The dialogue stays the endpoint's (one home: scpi_instrument.py): bytes
received go to its `write`, what it has to say (`read_available`) goes back. One client at a time, served by a
thread; loopback only.
"""

from __future__ import annotations

import logging
import selectors
import socket
import sys
import signal
import threading
from types import TracebackType

from sim_bench.emulators.registry import SerialEndpoint

log = logging.getLogger(__name__)
_POLL_S = 0.002


class ScpiSocketServer:
    """Serves `endpoint` on 127.0.0.1:`port` (0: a free port, see `.port`) until `close()`; a context manager."""

    def __init__(self, endpoint: SerialEndpoint, port: int = 0) -> None:
        self.endpoint = endpoint
        self._listener = socket.create_server(("127.0.0.1", port))
        self.port: int = self._listener.getsockname()[1]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name=f"scpi-socket-{self.port}", daemon=True)
        self._thread.start()

    @property
    def resource(self) -> str:
        """The VISA resource string of this server."""
        return f"TCPIP0::127.0.0.1::{self.port}::SOCKET"

    def close(self) -> None:
        """Stop serving and close the listening socket (a connected client sees the connection end)."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._listener.close()

    def __enter__(self) -> "ScpiSocketServer":
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def _serve(self) -> None:
        self._listener.settimeout(_POLL_S * 10)
        while not self._stop.is_set():
            try:
                client, peer = self._listener.accept()
            except (TimeoutError, socket.timeout):
                continue
            except OSError:
                return
            log.debug("SCPI socket %d: client %s", self.port, peer)
            with client:
                self._talk(client)

    def _talk(self, client: socket.socket) -> None:
        """Bytes in to the endpoint, its replies out, until the client leaves or the server stops."""
        client.setblocking(False)
        with selectors.DefaultSelector() as sel:
            sel.register(client, selectors.EVENT_READ)
            while not self._stop.is_set():
                if sel.select(_POLL_S):
                    try:
                        data = client.recv(4096)
                    except (BlockingIOError, InterruptedError):
                        continue
                    except OSError:
                        return
                    if not data:
                        return
                    self.endpoint.write(data)
                reply = self.endpoint.read_available()
                if reply:
                    try:
                        client.sendall(reply)
                    except OSError:
                        return


def main(argv: list[str] | None = None) -> int:
    """`python -m sim_bench.emulators.scpi_server [--port N]`: the SCPI emulator on 127.0.0.1 until Ctrl-C, for
    rehearsing a bench file's VISA resource `TCPIP0::127.0.0.1::N::SOCKET`."""
    import argparse

    from sim_bench.emulators.scpi_instrument import ScpiInstrumentEmulator

    parser = argparse.ArgumentParser(prog="python -m sim_bench.emulators.scpi_server",
                                     description="Serve the SCPI instrument emulator (the dialogue of sim://) as a raw "
                                                 "SCPI socket on 127.0.0.1 (loopback only) until Ctrl-C.")
    parser.add_argument("--port", type=int, default=5025,
                        help="TCP port on 127.0.0.1 (default 5025, a LAN instrument's; 0: a free port)")
    args = parser.parse_args(argv)
    if not 0 <= args.port <= 65535:
        parser.error(f"--port: a TCP port 0-65535, got {args.port}")
    try:
        server = ScpiSocketServer(ScpiInstrumentEmulator(), args.port)
    except OSError as exc:
        print(f"127.0.0.1:{args.port}: a free port to serve on ({exc.strerror})", file=sys.stderr)
        return 2
    stop = threading.Event()  # Ctrl-C sets it: no KeyboardInterrupt can land inside the server's close
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    with server:
        print(f"serving the SCPI emulator as {server.resource} (Ctrl-C stops)", flush=True)
        stop.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
