"""Batch work on this machine: in this process, or in a pool of worker processes of our own.

The pool knows which task each worker runs, so a worker that dies mid-task (a crash in native code,
the OOM killer, ``os._exit``) costs that task one attempt and nothing else: the task is sent again to a
fresh worker, the other workers go on. (``concurrent.futures.ProcessPoolExecutor`` would break the
whole pool and fail every task in flight, without telling which one killed it.)
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import signal
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Generator, Sequence
from typing import Any

from dlovr import signals
from dlovr.batch.core import Attempts, Task, TaskResult, call_task, one_line


def run_here(fn: Callable[..., Any], tasks: Sequence[Task]) -> Generator[TaskResult, None, None]:
    """Run the tasks one after the other in this process."""
    book = Attempts(tasks, 0, lambda _msg: None)
    for i, t in enumerate(tasks):
        book.count[i] = 1
        yield book.result(i, *call_task(fn, t.args, t.kwargs))


#: Seconds between two looks of a worker at its parent; the grace a worker has to finish its task's
#: files after SIGTERM before it is killed.
PARENT_POLL_S, STOP_GRACE_S = 0.5, 10.0


def _watch_parent(parent: int) -> None:
    """In a worker: when the parent process is gone (killed), end this worker as on SIGTERM (its task
    finishes its files), killed after :data:`STOP_GRACE_S`: an orphan never lives on holding the
    caller's pipes."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(STOP_GRACE_S)
    os._exit(128 + signal.SIGTERM)


def _worker_loop(conn: multiprocessing.connection.Connection, parent: int) -> None:
    """A worker process: run the tasks sent over ``conn`` until it closes or sends None. SIGTERM ends
    it (a :class:`dlovr.signals.SignalExit` through its task, so a recording in progress is
    finished); Ctrl-C is the parent's to handle."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signals.handler)
    signals.clear()  # the parent's, if it had one when this process was forked
    threading.Thread(target=_watch_parent, args=(parent,), name="dlovr-parent-watch", daemon=True).start()
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg is None:
            return
        out = call_task(*msg)
        try:
            conn.send(out)
        except Exception as e:  # a value that cannot be pickled
            conn.send((False, f"its result cannot be sent back: {one_line(e)}", out[2]))


class _Worker:
    """A worker process, its end of the pipe, and the index of the task it runs (None when idle)."""

    def __init__(self, ctx: Any):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_loop, args=(child, os.getpid()), name="dlovr-batch-worker")
        self.proc.start()
        child.close()
        self.task: int | None = None

    def death(self) -> str:
        """Why the (dead or dying) process ended, for the report."""
        self.proc.join(5.0)
        code = self.proc.exitcode
        if code is not None and code < 0:
            try:
                how = f"killed by {signal.Signals(-code).name}"
            except ValueError:
                how = f"killed by signal {-code}"
        else:
            how = f"exit code {code}" if code is not None else "stopped answering"
        return f"worker {socket.gethostname()}:{self.proc.pid} died ({how})"

    def stop(self, wait: bool) -> None:
        """Ask it to finish (``wait``) or kill it; close the pipe."""
        if wait and self.proc.is_alive():
            try:
                self.conn.send(None)
            except OSError:
                pass
            self.proc.join(2.0)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join(2.0)
        self.conn.close()


def _stop_all(workers: list[_Worker], clean: bool) -> None:
    """Stop every worker: idle ones asked to finish (``clean``), else each sent SIGTERM (a task
    writing a recording finishes it) and given :data:`STOP_GRACE_S` in all, then killed."""
    if not clean:
        for w in workers:
            if w.proc.is_alive():
                w.proc.terminate()
        end = time.monotonic() + STOP_GRACE_S
        for w in workers:
            w.proc.join(max(0.0, end - time.monotonic()))
    for w in workers:
        w.stop(wait=clean)


def run_on_processes(
    fn: Callable[..., Any],
    tasks: Sequence[Task],
    workers: int,
    retries: int,
    note: Callable[[str], None],
) -> Generator[TaskResult, None, None]:
    """Run the tasks on ``workers`` worker processes; yield results in order of completion.

    ``fn`` and the tasks' arguments are pickled (``fn`` by name). A task whose worker dies runs again on
    a fresh worker, at most ``retries`` more times; ``note`` gets a line for each loss.
    """
    ctx = multiprocessing.get_context()
    book = Attempts(tasks, retries, note)
    queue = deque(range(len(tasks)))
    idle: list[_Worker] = []
    running: dict[Any, _Worker] = {}  # pipe and sentinel of each busy worker -> worker
    clean = False
    try:
        while queue or running:
            while queue and len(running) < 2 * workers:
                w = idle.pop() if idle else _Worker(ctx)
                i = queue.popleft()
                try:
                    w.conn.send((fn, tasks[i].args, tasks[i].kwargs))
                except (BrokenPipeError, ConnectionResetError):  # it died while idle: not the task's fault
                    queue.appendleft(i)
                    w.stop(wait=False)
                    continue
                book.count[i] += 1
                w.task = i
                running[w.conn] = running[w.proc.sentinel] = w
            for obj in multiprocessing.connection.wait(list(running)):
                w = running.get(obj)
                if w is None or w.task is None:
                    continue  # its pipe and its sentinel were both ready: handled already
                out = None
                try:
                    if w.conn.poll():
                        out = w.conn.recv()
                except (EOFError, OSError):
                    pass
                if out is None and obj is w.conn and w.proc.is_alive():
                    continue  # the pipe closed but the process has not ended yet: wait for it
                i, w.task = w.task, None
                del running[w.conn], running[w.proc.sentinel]
                if out is not None:
                    idle.append(w)
                    yield book.result(i, *out)
                    continue
                reason = w.death()
                w.stop(wait=False)
                failed = book.worker_lost(i, reason)
                if failed is None:
                    queue.appendleft(i)
                else:
                    yield failed
        clean = True
    finally:
        _stop_all([*idle, *{id(w): w for w in running.values()}.values()], clean)
