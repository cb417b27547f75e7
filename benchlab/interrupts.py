"""Ctrl-C that Python swallowed, delivered again: `benchlab` always answers Ctrl-C (exit 130).

Python raises KeyboardInterrupt wherever the main thread is when SIGINT arrives. Inside a finaliser or a
weakref callback (h5py releases its objects through them) it can only print "Exception ignored ..." with
a traceback and carry on: a run interrupted during start-up then ran to its end and said "run complete".
While RedeliverInterrupts is active, such an interrupt is not printed but raised again a moment later,
when the main thread is back in ordinary code (and again, should it land in a callback once more).
Once the command has answered a Ctrl-C, `interrupts_answered` makes that answer the process's last word.
SIGTERM is answered the same way (`terminate_as_interrupt`: `Terminated`, exit 143), never by the default that
kills the process mid-way (a run's `.lock` left behind).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator
from types import TracebackType
from typing import Any


TERMINATED_EXIT = 128 + signal.SIGTERM
#: SIGINT and SIGTERM that arrived while note_interrupts' handler was in place (before the command line's handlers).
_noted: list[int] = []


class Terminated(KeyboardInterrupt):
    """SIGTERM, answered as Ctrl-C is (the run ends aborted, its files whole, its lock released), exit 143."""


def _raise_terminated(signum: int, frame: Any) -> None:
    raise Terminated


def _note(signum: int, frame: Any) -> None:
    _noted.append(signum)


def note_interrupts() -> None:
    """SIGINT and SIGTERM noted from now on, not acted upon, until `raise_noted` (the console script's first act:
    the default SIGTERM handler would kill the process before benchlab.cli has set its own)."""
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, _note)


def raise_noted() -> None:
    """Ctrl-C back to Python's KeyboardInterrupt if note_interrupts had it; an interrupt noted meanwhile raised
    (Terminated for SIGTERM) to be answered as any other."""
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is _note:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if _noted:
        terminated = signal.SIGTERM in _noted
        _noted.clear()
        raise Terminated if terminated else KeyboardInterrupt


@contextlib.contextmanager
def terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM raises `Terminated` in the main thread during the block (elsewhere the block runs as it is)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class RedeliverInterrupts:
    """Context manager: a swallowed Ctrl-C is sent again after `delay_s`; `swallowed` says one was still pending
    when the block ended (the caller then reports the interrupt itself)."""

    def __init__(self, delay_s: float = 0.05) -> None:
        self.delay_s = delay_s
        self.swallowed = False
        self._timer: threading.Timer | None = None
        self._lock = threading.Lock()
        self._previous_hook = sys.unraisablehook

    def __enter__(self) -> "RedeliverInterrupts":
        self._previous_hook = sys.unraisablehook
        sys.unraisablehook = self._hook
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        sys.unraisablehook = self._previous_hook
        with self._lock:
            timer, self._timer = self._timer, None
        if timer is not None:
            timer.cancel()
            self.swallowed = True

    def _hook(self, unraisable: Any) -> None:
        if unraisable.exc_type is None or not issubclass(unraisable.exc_type, KeyboardInterrupt):
            self._previous_hook(unraisable)
            return
        with self._lock:
            if self._timer is None:
                self._timer = threading.Timer(self.delay_s, self._deliver)
                self._timer.daemon = True
                self._timer.start()

    def _deliver(self) -> None:
        with self._lock:  # sent under the lock: __exit__ either cancels it or finds it sent (and raised)
            if self._timer is None:  # the block has ended: nothing to interrupt any more
                return
            self._timer = None
            os.kill(os.getpid(), signal.SIGINT)


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Ctrl-C (SIGINT) noted during the block and raised as KeyboardInterrupt when it ends.

    For imports: a Ctrl-C that lands while an extension module initialises (numpy's, importing `datetime` in C)
    surfaces as that module's ImportError, not as KeyboardInterrupt, and the command would fail instead of
    answering the interrupt. Noted by a handler that raises nothing, it is raised after, in ordinary code.
    Only the main thread can set handlers; elsewhere the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: caught.append(signum))
                for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if caught:
            raise Terminated if signal.SIGTERM in caught else KeyboardInterrupt


def interrupts_answered() -> None:
    """Ctrl-C has been answered (exit 130): later ones are ignored while the process ends, and the interpreter
    forgets the interrupt, so that the process exits with the code it was given.

    CPython records a KeyboardInterrupt that leaves source text run by exec() or eval() as unhandled, even when
    caught later (dataclasses, namedtuple and numba make their functions from source text: a Ctrl-C while a
    module imports lands there); `python -m` then ends by sending itself SIGINT (exit -2) whatever sys.exit
    asked. Running source text again clears that record: CPython resets it whenever it starts source text.
    """
    if threading.current_thread() is threading.main_thread():  # only the main thread can set handlers
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # before the exec: no Ctrl-C can land in it and record anew
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    exec("", {})  # noqa: S102 - a constant empty source: see above
