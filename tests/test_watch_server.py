"""The live view's server as a careful small server (issue 30): half-open connections time out, connections are
bounded (503 beyond), one Host header naming this computer, absolute-form targets naming another host refused, and
a client that goes away is a debug line, never a traceback. All on 127.0.0.1."""

from __future__ import annotations

import socket
import struct
import time
from collections.abc import Callable

import pytest

from benchlab.cli import configure_logging
from benchlab.watch import server as watch_server
from test_watch import serving  # tests/test_watch.py

#: The time-out and bound the tests give the server (its own are READ_TIMEOUT_S, MAX_CONNECTIONS): small, so the
#: tests stay short.
TIMEOUT_S = 0.5
CONNECTIONS = 3


@pytest.fixture()
def served(run_file):
    with serving(run_file, read_timeout_s=TIMEOUT_S, max_connections=CONNECTIONS) as server:
        yield server


def _connect(server: watch_server.WatchServer) -> socket.socket:
    sock = socket.create_connection(server.server_address, timeout=10)
    return sock


def _ask(server: watch_server.WatchServer, request: str) -> tuple[int, bytes]:
    """Send a raw request; the status code and the whole answer (the server closes or keeps the connection)."""
    with _connect(server) as sock:
        sock.sendall(request.encode())
        answer = b""
        while b"\r\n\r\n" not in answer:
            chunk = sock.recv(65536)
            if not chunk:
                break
            answer += chunk
    return int(answer.split(b" ", 2)[1]), answer


def _host(server: watch_server.WatchServer) -> str:
    return f"127.0.0.1:{server.server_address[1]}"


def test_the_server_listens_on_the_loopback_address_only(served):
    assert served.server_address[0] == "127.0.0.1"
    assert _ask(served, f"GET / HTTP/1.1\r\nHost: {_host(served)}\r\n\r\n")[0] == 200


@pytest.mark.parametrize("headers, code", [
    ("Host: {host}\r\nHost: evil.example\r\n", 400),   # two Host headers, the valid one first (RFC 9112: 400)
    ("Host: evil.example\r\nHost: {host}\r\n", 400),
    ("Host: {host}\r\nHost: {host}\r\n", 400),
    ("", 400),                                         # none
    ("Host: evil.example\r\n", 403),
    ("Host: {host}\r\n", 200),
])
def test_exactly_one_host_header_naming_this_computer(served, headers, code):
    request = "GET /api/update?width=10 HTTP/1.1\r\n" + headers.format(host=_host(served)) + "\r\n"
    assert _ask(served, request)[0] == code


@pytest.mark.parametrize("target, code", [
    ("http://evil.example/api/update?width=10", 400),
    ("http://evil.example:{port}/", 400),
    ("https://{host}/", 400),
    ("ftp://{host}/", 400),
    ("*", 400),
    ("api/update", 400),
    ("http://{host}/api/update?width=10", 200),       # absolute form naming this computer: served
])
def test_an_absolute_form_target_naming_another_host_is_refused(served, target, code):
    target = target.format(host=_host(served), port=served.server_address[1])
    assert _ask(served, f"GET {target} HTTP/1.1\r\nHost: {_host(served)}\r\n\r\n")[0] == code


def _closed_by_server(sock: socket.socket) -> bool:
    """Whether the server closed the connection: recv sees the end (or a reset) before the client's time-out."""
    try:
        return sock.recv(1) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


def _wait(condition: Callable[[], bool], limit_s: float = 10.0) -> bool:
    deadline = time.monotonic() + limit_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def test_half_open_connections_time_out(served):
    """200 connections that send nothing (or half a request line) used to hold 200 threads for ever: each is closed
    by the server after its read time-out, without an answer, and its slot serves the next request."""
    idle = [_connect(served) for _ in range(CONNECTIONS)]
    for sock in idle[::2]:
        sock.sendall(b"GET /api/upd")  # half a request line, never finished
    try:
        assert _wait(lambda: served.slots._value == 0)  # all held
        assert all(_closed_by_server(sock) for sock in idle)  # each recv waits at most its 10 s
    finally:
        for sock in idle:
            sock.close()
    assert _ask(served, f"GET / HTTP/1.1\r\nHost: {_host(served)}\r\n\r\n")[0] == 200


def test_connections_beyond_the_bound_are_answered_503_and_served_again_once_free(served):
    held = [_connect(served) for _ in range(CONNECTIONS)]
    for sock in held:
        sock.sendall(b"GET / HTTP/1.1\r\n")  # a request begun: each holds its slot until it times out
    try:
        assert _wait(lambda: served.slots._value == 0)
        code, answer = _ask(served, f"GET / HTTP/1.1\r\nHost: {_host(served)}\r\n\r\n")
        assert code == 503 and b"Retry-After" in answer
    finally:
        for sock in held:
            sock.close()
    assert _wait(lambda: served.slots._value == CONNECTIONS)
    assert _ask(served, f"GET / HTTP/1.1\r\nHost: {_host(served)}\r\n\r\n")[0] == 200


def test_a_client_that_resets_mid_answer_is_a_debug_line_not_a_traceback(served, capsys):
    """A browser tab closed during a poll used to print a full traceback. Logged as `benchlab -vv watch` logs."""
    configure_logging(2)  # benchlab's DEBUG lines on stderr, as the CLI's -vv sets them up
    try:
        request = f"GET /api/update?width=8192 HTTP/1.1\r\nHost: {_host(served)}\r\n\r\n".encode()
        seen: list[str] = []
        for _ in range(20):
            sock = _connect(served)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # close = reset
            sock.sendall(request)
            sock.close()
        assert _wait(lambda: seen.append(capsys.readouterr().err) or "went away" in "".join(seen))
        time.sleep(2 * TIMEOUT_S)  # any connection still open has timed out by now
        seen.append(capsys.readouterr().err)
    finally:
        configure_logging(0)
    text = "".join(seen)
    assert "Traceback" not in text and "ERROR" not in text
    assert all(line.startswith("DEBUG benchlab.watch.server: ") for line in text.splitlines()), text
    assert _ask(served, f"GET / HTTP/1.1\r\nHost: {_host(served)}\r\n\r\n")[0] == 200
