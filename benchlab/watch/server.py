"""The live view's web server: the page (static/), and its updates as JSON, on 127.0.0.1 only.

GET /                 the page (index.html, watch.js: plain <canvas> drawing, nothing fetched from elsewhere)
GET /api/update?...   LiveRun.update: width (px), span (s, 0 = whole run), level, have, events; JSON
Requests that name another host than the loopback address are refused (no DNS rebinding onto the bench PC).
"""

from __future__ import annotations

import errno
import json
import socket
import threading
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlsplit

from benchlab.errors import InputError
from benchlab.watch.live import LiveRun

HOST = "127.0.0.1"
STATIC = {"/": ("index.html", "text/html; charset=utf-8"), "/watch.js": ("watch.js", "text/javascript; charset=utf-8")}
MAX_WIDTH = 8192  # px: a plot wider than any screen would only make answers bigger


def listen(port: int) -> socket.socket:
    """A listening socket on 127.0.0.1:`port` (0: a free one); a port in use is bad input (exit 2)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # not a second listener: only TIME_WAIT leftovers
    try:
        sock.bind((HOST, port))
        sock.listen(16)
    except OSError as exc:
        sock.close()
        why = "in use" if exc.errno == errno.EADDRINUSE else exc.strerror
        raise InputError("command line", "--port", f"a free TCP port on {HOST} (port {port}: {why})") from None
    return sock


def _static(name: str) -> bytes:
    return resources.files("benchlab.watch").joinpath("static", name).read_bytes()


class WatchServer(ThreadingHTTPServer):
    """ThreadingHTTPServer on a socket from `listen`, answering for one LiveRun."""

    daemon_threads = True

    def __init__(self, live: LiveRun, sock: socket.socket) -> None:
        super().__init__(sock.getsockname(), _Handler, bind_and_activate=False)
        self.socket.close()
        self.socket = sock
        self.live = live
        self.pages = {path: (_static(name), kind) for path, (name, kind) in STATIC.items()}
        port = sock.getsockname()[1]
        self.hosts = {f"{HOST}:{port}", f"localhost:{port}"}

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.server_address[1]}/"


def _int(query: dict[str, list[str]], name: str, default: int | None, low: int, high: int) -> int | None:
    if name not in query:
        return default
    value = int(query[name][0])  # ValueError: a bad request
    if not low <= value <= high:
        raise ValueError(f"{name} outside [{low}, {high}]")
    return value


class _Handler(BaseHTTPRequestHandler):
    server: WatchServer
    protocol_version = "HTTP/1.1"

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        if self.headers.get("Host") not in self.server.hosts:
            self._send(HTTPStatus.FORBIDDEN, b"only for this computer (127.0.0.1)", "text/plain")
            return
        url = urlsplit(self.path)
        if url.path in self.server.pages:
            body, kind = self.server.pages[url.path]
            self._send(HTTPStatus.OK, body, kind)
        elif url.path == "/api/update":
            self._update(parse_qs(url.query))
        else:
            self._send(HTTPStatus.NOT_FOUND, b"not found", "text/plain")

    def _update(self, query: dict[str, list[str]]) -> None:
        try:
            args: dict[str, Any] = {
                "width": _int(query, "width", 1000, 1, MAX_WIDTH), "span_s": float(_int(query, "span", 0, 0, 10**9)),
                "level": _int(query, "level", None, 0, 64), "have": _int(query, "have", 0, 0, 2**62),
                "events_from": _int(query, "events", None, 0, 2**62)}
        except ValueError as exc:
            self._send(HTTPStatus.BAD_REQUEST, json.dumps({"error": str(exc)}).encode(), "application/json")
            return
        try:
            answer = self.server.live.update(**args)
        except OSError as exc:  # the file could not be read this time: the page says so and asks again
            self._send(HTTPStatus.SERVICE_UNAVAILABLE, json.dumps({"error": str(exc)}).encode(), "application/json")
            return
        self._send(HTTPStatus.OK, json.dumps(answer, allow_nan=False).encode(), "application/json")

    def _send(self, code: HTTPStatus, body: bytes, kind: str) -> None:
        self.send_response(code)
        self.send_header("Content-Type", kind)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - http.server's signature
        """Quiet: a page polling every second would fill the terminal."""


def serve(live: LiveRun, sock: socket.socket, stop: threading.Event | None = None) -> None:
    """Serve until `stop` is set, or until interrupted (KeyboardInterrupt propagates: the CLI's exit 130)."""
    server = WatchServer(live, sock)
    if stop is not None:
        threading.Thread(target=lambda: (stop.wait(), server.shutdown()), daemon=True).start()
    try:
        server.serve_forever(poll_interval=0.25)
    finally:
        server.server_close()
        live.close()
