"""Task functions for the batch tests: importable by name in worker processes and Ray workers."""

from __future__ import annotations

import hashlib
import os
import signal
import time
from pathlib import Path

import numpy as np


def seeded(seed: int, n: int = 20000) -> str:
    """A value that depends on the seed only (a digest of a seeded random walk)."""
    x = np.random.default_rng(seed).standard_normal(n)
    return hashlib.sha256(np.cumsum(np.sin(x) * x).tobytes()).hexdigest()


def die_once(seed: int, victim: int, marker: str, how: str = "exit") -> str:
    """``seeded(seed)``, but task ``victim`` kills its own process the first time (marker file)."""
    if seed == victim and not Path(marker).exists():
        Path(marker).write_text(str(os.getpid()))
        if how == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        os._exit(13)
    return seeded(seed)


def always_die(seed: int, victim: int) -> str:
    """``seeded(seed)``, but task ``victim`` kills its own process every time."""
    if seed == victim:
        os.kill(os.getpid(), signal.SIGKILL)
    return seeded(seed)


def fail_on(seed: int, bad: int) -> int:
    """Raise for ``bad``: an error in the task itself, not a lost worker."""
    if seed == bad:
        raise ValueError(f"seed {seed} is bad\nsecond line")
    return seed


def wait_for(seed: int, marker: str) -> int:
    """Task 0 waits (at most 60 s) for the marker that task 2 writes, so with two workers task 1 (run
    before task 2 on the other worker) completes before task 0."""
    if seed == 0:
        t0 = time.monotonic()
        while not Path(marker).exists() and time.monotonic() - t0 < 60:
            time.sleep(0.01)
    elif seed == 2:
        Path(marker).write_text("x")
    return seed


def call_or_die(fn, mode: str, marker: str, *args):
    """``fn(*args)``, but first kill this process with SIGKILL: the first time (``mode`` "once", the
    marker file not yet written) or every time (``mode`` "always")."""
    if mode == "always" or (mode == "once" and not Path(marker).exists()):
        Path(marker).write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    return fn(*args)


def pid_then_sleep(seed: int, folder: str, seconds: float = 60.0) -> int:
    """Write this worker's pid to ``folder/<seed>.pid``, then sleep (task 0 returns at once): a task
    that is still running when the batch is interrupted or its parent killed."""
    Path(folder, f"{seed}.pid").write_text(str(os.getpid()))
    if seed > 0:
        time.sleep(seconds)
    return seed
