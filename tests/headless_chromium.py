"""Debian's headless Chromium driven over the DevTools protocol on a pipe (--remote-debugging-pipe), stdlib only.

Chromium reads commands from its fd 3 and writes answers and events to its fd 4, one JSON message per NUL.
`posix_spawn` puts our pipe ends there (no preexec_fn, safe beside the test's server threads).
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

CHROMIUM = "/usr/bin/chromium"
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--remote-debugging-pipe", "--window-size=1280,1600", "--hide-scrollbars")


def _high(fd: int) -> int:
    """The same pipe end on a descriptor above 9, so the child's dup2 onto 3 and 4 cannot overwrite it."""
    high = fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10)
    os.close(fd)
    return high


def available() -> str | None:
    """Why Chromium cannot be used here, or None if it can."""
    if not os.access(CHROMIUM, os.X_OK):
        return f"{CHROMIUM} not installed (Debian package chromium; .ci/run installs it)"
    return None


class Chromium:
    """One headless Chromium with one page; `evaluate` runs JavaScript in it, `screenshot` returns a PNG."""

    def __init__(self, timeout_s: float = 60.0) -> None:
        self.timeout_s = timeout_s
        self.profile = tempfile.mkdtemp(prefix="benchlab-chromium-")
        to_browser_r, self._to_browser = map(_high, os.pipe())
        self._from_browser, from_browser_w = map(_high, os.pipe())
        log = os.path.join(self.profile, "chromium.log")
        actions = [(os.POSIX_SPAWN_DUP2, to_browser_r, 3), (os.POSIX_SPAWN_DUP2, from_browser_w, 4),
                   (os.POSIX_SPAWN_OPEN, 1, log, os.O_WRONLY | os.O_CREAT, 0o600),
                   (os.POSIX_SPAWN_DUP2, 1, 2)]
        argv = [CHROMIUM, *FLAGS, f"--user-data-dir={self.profile}", "about:blank"]
        self.pid = os.posix_spawn(CHROMIUM, argv, os.environ, file_actions=actions)
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._buffer = b""
        self._next_id = 0
        targets = self.call("Target.getTargets")["targetInfos"]
        page = next(t for t in targets if t["type"] == "page")
        self.session = self.call("Target.attachToTarget", targetId=page["targetId"], flatten=True)["sessionId"]

    def call(self, method: str, session: str | None = None, **params: Any) -> dict[str, Any]:
        """Send one command and wait for its answer (events meanwhile are dropped)."""
        self._next_id += 1
        message: dict[str, Any] = {"id": self._next_id, "method": method, "params": params}
        if session:
            message["sessionId"] = session
        os.write(self._to_browser, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + self.timeout_s
        while time.monotonic() < deadline:
            while b"\0" not in self._buffer:
                chunk = os.read(self._from_browser, 1 << 16)
                if not chunk:
                    raise RuntimeError(f"chromium closed the pipe: {self.log()[-2000:]}")
                self._buffer += chunk
            raw, self._buffer = self._buffer.split(b"\0", 1)
            answer = json.loads(raw)
            if answer.get("id") == self._next_id:
                if "error" in answer:
                    raise RuntimeError(f"{method}: {answer['error']}")
                return answer["result"]
        raise TimeoutError(f"{method}: no answer in {self.timeout_s} s")

    def page(self, method: str, **params: Any) -> dict[str, Any]:
        return self.call(method, self.session, **params)

    def navigate(self, url: str) -> None:
        self.page("Page.navigate", url=url)

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression in the page (JSON-able)."""
        result = self.page("Runtime.evaluate", expression=expression, returnByValue=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression}: {result['exceptionDetails']}")
        return result["result"].get("value")

    def screenshot(self, path: Path) -> bytes:
        data = base64.b64decode(self.page("Page.captureScreenshot", format="png")["data"])
        path.write_bytes(data)
        return data

    def log(self) -> str:
        return Path(self.profile, "chromium.log").read_text(errors="replace")

    def close(self) -> None:
        try:
            os.write(self._to_browser, json.dumps({"id": 0, "method": "Browser.close"}).encode() + b"\0")
        except OSError:
            pass
        for _ in range(100):
            pid, _status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                break
            time.sleep(0.05)
        else:
            os.kill(self.pid, 9)
            os.waitpid(self.pid, 0)
        os.close(self._to_browser)
        os.close(self._from_browser)
        shutil.rmtree(self.profile, ignore_errors=True)


#: What a hostile sender puts in a run attribute, a channel name or a file name: a blank line and raw HTML with
#: scripts, a javascript: link, an image whose error handler runs. Each sets `window.pwned` and the page's title.
HOSTILE = ("x\n\n<details><script>window.pwned=1;document.title='pwned'</script>\n\n"
           "<img src=nowhere onerror=\"window.pwned=2;document.title='pwned'\"> "
           "[click](javascript:window.pwned=3) ![f](javascript:window.pwned=4) `a`b|c **d** _e_ *f* &amp; \\<")
#: What a page holds once loaded: whether a script ran, the script elements and event handlers in it, every
#: address it links to or loads.
PAGE_STATE = """(() => ({pwned: window.pwned === undefined ? null : window.pwned, title: document.title,
  scripts: document.querySelectorAll('script').length,
  handlers: [...document.querySelectorAll('*')].flatMap(e => [...e.attributes].map(a => a.name))
            .filter(n => n.startsWith('on')).length,
  addresses: [...document.querySelectorAll('[href],[src]')].map(e => e.href || e.src),
  text: document.body.innerText}))()"""


def page_state(browser: Chromium, page: Path) -> dict[str, Any]:
    """Open a page from disk, wait for it to load and say what it holds (PAGE_STATE)."""
    browser.navigate(page.resolve().as_uri())
    deadline = time.monotonic() + browser.timeout_s
    while browser.evaluate("document.readyState") != "complete" and time.monotonic() < deadline:
        time.sleep(0.05)
    return browser.evaluate(PAGE_STATE)


def assert_inert(state: dict[str, Any], title: str) -> None:
    """A page that ran no script of a stranger: no script element, no handler, its own title, only file: and
    http(s) addresses, and the hostile text shown as text."""
    assert state["pwned"] is None and state["title"] == " ".join(title.split())  # as a browser shows a title
    assert state["scripts"] == 0 and state["handlers"] == 0
    assert all(a.split(":", 1)[0] in ("file", "http", "https") for a in state["addresses"]), state["addresses"]
    assert "<script>" in state["text"] and "javascript:window.pwned=3" in state["text"], state["text"][:3000]
