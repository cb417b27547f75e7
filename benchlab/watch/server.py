"""The live view's web server: the page (static/), and its updates as JSON, on 127.0.0.1 only.

GET /                 the page (index.html, watch.js: plain <canvas> drawing, nothing fetched from elsewhere)
GET /api/update?...   LiveRun.update: width (px), span (s, 0 = whole run), level, have, events; JSON
Requests that name another host than the loopback address are refused (no DNS rebinding onto the bench PC):
403 for a Host header naming another host, 400 for none or two Host headers (RFC 9112 section 3.2) and for an
absolute-form target (`GET http://other.example/...`) naming another host.

A careful small server: each connection has READ_TIMEOUT_S to send a request (a half-open connection is closed
after it, not held for ever), at most MAX_CONNECTIONS are served at once (the next is answered 503 and closed), and a
client that goes away mid-answer (a browser tab closed during a poll) is a debug line of the `benchlab.watch` log,
never a traceback.
"""

from __future__ import annotations

import errno
import json
import logging
import socket
import sys
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
#: Seconds a connection may take to send a request (and to take an answer): the page asks every second.
READ_TIMEOUT_S = 10.0
#: Connections served at once: a few pages polling need a handful; each holds a thread.
MAX_CONNECTIONS = 32
#: What a client going away looks like to the server: nothing to tell but a debug line.
CLIENT_GONE = (ConnectionError, TimeoutError)
BUSY = (b"HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\nContent-Length: 4\r\nRetry-After: 1\r\n"
        b"Connection: close\r\n\r\nbusy")
log = logging.getLogger(__name__)


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

    def __init__(self, live: LiveRun, sock: socket.socket, read_timeout_s: float = READ_TIMEOUT_S,
                 max_connections: int = MAX_CONNECTIONS) -> None:
        super().__init__(sock.getsockname(), _Handler, bind_and_activate=False)
        self.socket.close()
        self.socket = sock
        self.live = live
        self.pages = {path: (_static(name), kind) for path, (name, kind) in STATIC.items()}
        port = sock.getsockname()[1]
        self.hosts = {f"{HOST}:{port}", f"localhost:{port}"}
        self.read_timeout_s = read_timeout_s
        self.max_connections = max_connections
        self.slots = threading.BoundedSemaphore(max_connections)

    def process_request(self, request: Any, client_address: Any) -> None:
        """A thread for the connection while fewer than MAX_CONNECTIONS are served; else 503 and closed."""
        if not self.slots.acquire(blocking=False):
            log.debug("%s: %d connections already served, answered 503", client_address, self.max_connections)
            try:
                request.settimeout(1.0)
                request.sendall(BUSY)
            except OSError:
                pass
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            self.slots.release()
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            self.slots.release()

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A client that went away is a debug line; anything else one error line (its traceback with -vv)."""
        exc = sys.exc_info()[1]
        if isinstance(exc, CLIENT_GONE):
            log.debug("%s went away: %s", client_address, exc)
        else:
            log.error("%s: request failed: %s: %s", client_address, type(exc).__name__, exc)
            log.debug("request failed", exc_info=True)

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

    def setup(self) -> None:
        self.timeout = self.server.read_timeout_s  # per connection: the socket's time-out for every read and write
        super().setup()

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        hosts = self.headers.get_all("Host") or []
        if len(hosts) != 1:
            self._send(HTTPStatus.BAD_REQUEST, b"exactly one Host header", "text/plain")
            return
        if hosts[0] not in self.server.hosts:
            self._send(HTTPStatus.FORBIDDEN, b"only for this computer (127.0.0.1)", "text/plain")
            return
        url = urlsplit(self.path)
        if not self.path.startswith("/") and (url.scheme not in ("http", "") or url.netloc not in self.server.hosts):
            self._send(HTTPStatus.BAD_REQUEST, b"a path, or an absolute URL of this computer (127.0.0.1)",
                       "text/plain")
            return
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
        """Debug lines only (`benchlab -vv watch`): a page polling every second would fill the terminal."""
        log.debug("%s %s", self.address_string(), format % args)


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
