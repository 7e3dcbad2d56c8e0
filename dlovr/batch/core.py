"""Values and bookkeeping shared by the batch engines: tasks, results, attempts, cluster addresses."""

from __future__ import annotations

import importlib.util
import os
import socket
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from dlovr import signals
from dlovr.inputs import InputError

INSTALL_HINT = "pip install 'dlovr[ray]'"


class BatchError(InputError):
    """A cluster that cannot be used (Ray missing, bad address, unreachable): one line, which the
    command line reports with exit code 2."""


@dataclass(frozen=True)
class Task:
    """One call of the batch's function: ``fn(*args, **kwargs)``; ``key`` names it in results."""

    key: str
    args: tuple[Any, ...] = ()
    kwargs: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class TaskResult:
    """A task's outcome: its ``value``, or ``error`` (one line) when it raised or every attempt's
    worker died. ``index`` is the task's place in the batch; ``attempts`` counts the runs it took
    (> 1: run again after a lost worker, the reasons in ``lost``); ``where`` is ``host:pid`` of the
    process that finished it (``""`` if none did)."""

    key: str
    index: int
    value: Any = None
    error: str | None = None
    attempts: int = 1
    where: str = ""
    lost: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def retried(self) -> bool:
        return self.attempts > 1


@dataclass(frozen=True)
class BatchSummary:
    """Counts over a batch's results (``retried``: tasks that needed more than one attempt)."""

    total: int
    ok: int
    failed: int
    retried: int

    def __str__(self) -> str:
        return f"{self.total} tasks: {self.ok} done, {self.failed} failed, {self.retried} retried"


def summarize(results: Sequence[TaskResult]) -> BatchSummary:
    """Count done, failed and retried tasks."""
    failed = sum(1 for r in results if not r.ok)
    return BatchSummary(len(results), len(results) - failed, failed, sum(1 for r in results if r.retried))


def here() -> str:
    """``host:pid`` of this process."""
    return f"{socket.gethostname()}:{os.getpid()}"


def one_line(e: BaseException) -> str:
    """An exception as ``Type: message`` on one line."""
    text = " ".join(str(e).split())
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def call_task(fn: Callable[..., Any], args: tuple[Any, ...], kwargs: Mapping[str, Any]) -> tuple:
    """Run one task: ``(True, value, where)``, or ``(False, "Type: message", where)`` if it raised."""
    try:
        return True, fn(*args, **kwargs), here()
    except Exception as e:
        return False, one_line(e), here()
    except SystemExit as e:
        if isinstance(e, signals.SignalExit) or signals.pending() is not None:
            raise  # a signal ends the batch, not just this task
        return False, f"SystemExit: {e.code}", here()


class Attempts:
    """The engines' bookkeeping: attempts per task and why earlier ones were lost."""

    def __init__(self, tasks: Sequence[Task], retries: int, note: Callable[[str], None]):
        self.tasks, self.retries, self.note = tasks, retries, note
        self.count = [0] * len(tasks)
        self.lost: list[list[str]] = [[] for _ in tasks]

    def result(self, i: int, ok: bool, payload: Any, where: str) -> TaskResult:
        """Task ``i``'s result from ``call_task``'s triple."""
        t = self.tasks[i]
        value, error = (payload, None) if ok else (None, payload)
        return TaskResult(t.key, i, value, error, self.count[i], where, tuple(self.lost[i]))

    def worker_lost(self, i: int, reason: str) -> TaskResult | None:
        """Record that task ``i``'s worker died: None when it should run again, else its failure."""
        self.lost[i].append(reason)
        key, n = self.tasks[i].key, self.count[i]
        if n <= self.retries:
            self.note(f"{key}: {reason} (attempt {n}); running it again")
            return None
        self.note(f"{key}: {reason} (attempt {n}); giving up")
        return self.result(i, False, f"{key}: worker lost on each of {n} attempts (last: {reason})", "")


def ray_installed() -> bool:
    """Whether Ray can be imported (without importing it)."""
    try:
        return importlib.util.find_spec("ray") is not None
    except (ImportError, ValueError):  # ValueError: sys.modules["ray"] is None
        return False


def host_port(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of ``HOST:PORT`` or ``ray://HOST:PORT``; None if it is neither."""
    rest = address.removeprefix("ray://")
    host, sep, port = rest.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        return None
    return host.strip("[]"), int(port)


def check_cluster(cluster: str | None) -> str | None:
    """Validate a ``--cluster`` value (``local``, ``auto``, ``HOST:PORT``, ``ray://HOST:PORT``) and
    that Ray is installed; raise :class:`BatchError` (one line) otherwise."""
    if cluster is None:
        return None
    if cluster not in ("local", "auto") and host_port(cluster) is None:
        raise BatchError(f"--cluster {cluster}: expected local, auto or HOST:PORT (e.g. 10.0.0.5:6379)")
    if not ray_installed():
        raise BatchError(f"--cluster needs Ray, which is not installed: {INSTALL_HINT}")
    return cluster
