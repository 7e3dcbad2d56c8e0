"""The project's on-disk cache directory (convex decompositions, mesh checks, compiled kernels when the
package directory is read-only): ``$DLOVR_CACHE_DIR``, else ``$XDG_CACHE_HOME/dlovr``, else
``~/.cache/dlovr``; and what a slow step computing something for it says (:func:`slow_step`)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path


def cache_dir() -> Path:
    """The cache directory (not created here)."""
    env = os.environ.get("DLOVR_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "dlovr"


#: Told one line before and after a slow step whose result is then cached (a large mesh's convex
#: decomposition...): the command line prints it on stderr (:func:`set_reporter`); None: silent (a
#: library user, a worker process).
_reporter: Callable[[str], None] | None = None


def set_reporter(report: Callable[[str], None] | None) -> None:
    """Where :func:`slow_step` says what it does (the command line: a line on stderr)."""
    global _reporter
    _reporter = report


@contextmanager
def slow_step(what: str) -> Iterator[None]:
    """Say ``what...`` before a slow step and ``what: done in N s`` after it (nothing without a
    reporter), so that a long load shows what it is doing."""
    report = _reporter
    if report is None:
        yield
        return
    report(f"{what}...")
    t0 = time.monotonic()
    yield
    report(f"{what}: done in {time.monotonic() - t0:.1f} s")
