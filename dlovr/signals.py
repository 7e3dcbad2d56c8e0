"""SIGINT (Ctrl-C) and SIGTERM at any moment of a ``dlovr`` command, start-up included.

A dependency may swallow the ``KeyboardInterrupt`` a signal raises: trimesh wraps its optional imports
in ``except BaseException``, so a Ctrl-C while it is imported was lost and the command ran to the end
with exit 0. So the handlers :func:`install` sets do two things: they raise (``KeyboardInterrupt`` for
SIGINT, :class:`SignalExit` for SIGTERM), and they remember the signal (:func:`pending`), which is never
lost: a recording loop (:class:`dlovr.recording.StopSignals`) takes a pending signal as its stop
request, and the command line checks it when a command returns (:func:`check`). Exit status 128 +
the signal's number: 130 for SIGINT, 143 for SIGTERM.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, NoReturn

SIGNALS = (signal.SIGINT, signal.SIGTERM)

_pending: int | None = None


class SignalExit(SystemExit):
    """Raised by the SIGTERM handler: a ``SystemExit`` (exit 143) that says where it came from."""

    def __init__(self, signum: int) -> None:
        super().__init__(exit_code(signum))
        self.signum = signum


def exit_code(signum: int) -> int:
    """The conventional exit status of a command ended by ``signum`` (128 + its number)."""
    return 128 + int(signum)


def name(signum: int) -> str:
    """``SIGINT``, ``SIGTERM``."""
    return signal.Signals(signum).name


def pending() -> int | None:
    """The first signal received since :func:`install` (or :func:`clear`), else None."""
    return _pending


def note(signum: int) -> None:
    """Remember ``signum`` as received (the first one counts)."""
    global _pending
    if _pending is None:
        _pending = int(signum)


def clear() -> int | None:
    """Forget the pending signal (it was handled); return it."""
    global _pending
    signum, _pending = _pending, None
    return signum


def interrupt(signum: int) -> NoReturn:
    """Raise what ``signum`` raises: ``KeyboardInterrupt`` for SIGINT, else :class:`SignalExit`."""
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise SignalExit(signum)


def handler(signum: int, frame: Any) -> None:
    """The handler :func:`install` sets: remember the signal, then interrupt, unless a module is being
    imported: an interruption there can leave a dependency half-imported (trimesh then keeps a
    placeholder for an optional module, and a later ``placeholder | None`` fails with a ``TypeError``).
    The signal stays pending, and the command ends at its next check (:func:`check`, the recording
    loop's stop request, or the command's return). The same holds inside numba's compiler, whose ctypes
    callbacks drop an exception with a traceback on stderr."""
    note(signum)
    if not _unsafe(frame):
        interrupt(signum)


#: Where raising would do harm: Python's import machinery, and numba's compiler (llvmlite calls back
#: into Python through ctypes, which prints and drops an exception raised there).
_UNSAFE = ("<frozen importlib", "/llvmlite/", "/numba/")


def _unsafe(frame: Any) -> bool:
    """Whether ``frame`` or a frame it was called from is in :data:`_UNSAFE` code."""
    while frame is not None:
        name = frame.f_code.co_filename
        if name.startswith(_UNSAFE[0]) or any(part in name for part in _UNSAFE[1:]):
            return True
        frame = frame.f_back
    return False


def defer() -> None:
    """From now on SIGINT and SIGTERM are only remembered (:func:`pending`), nothing is raised: for
    the start of the program, before the command line is ready to end a command cleanly
    (``dlovr/__init__.py`` calls it first when the process is the ``dlovr`` script or
    ``python -m dlovr``)."""
    if threading.current_thread() is threading.main_thread():
        for sig in SIGNALS:
            signal.signal(sig, lambda signum, _frame: note(signum))


def check() -> None:
    """Raise the pending signal's interruption, if one came (and was swallowed on its way)."""
    if _pending is not None:
        interrupt(_pending)


@contextmanager
def installed(signals: tuple[int, ...] = SIGNALS) -> Iterator[None]:
    """:func:`handler` for ``signals`` while inside (the previous handlers back afterwards); outside
    the main thread nothing is installed."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, handler) for sig in signals}
    try:
        yield
    finally:
        for sig, prev in previous.items():
            signal.signal(sig, prev)


__all__ = [
    "SIGNALS",
    "SignalExit",
    "check",
    "clear",
    "defer",
    "exit_code",
    "handler",
    "installed",
    "interrupt",
    "name",
    "note",
    "pending",
]
