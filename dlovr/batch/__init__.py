"""Batch work: one function over many tasks, on local processes (the default) or a Ray cluster.

:func:`run_batch` runs ``fn(*task.args, **task.kwargs)`` for every :class:`Task` and yields a
:class:`TaskResult` for each as it completes (order of completion; ``index`` is the task's place):

- ``cluster=None``: this machine. ``workers=1`` (or ``None``) runs the tasks one after the other in
  this process; ``workers=N`` in N worker processes (:mod:`dlovr.batch.local`);
- ``cluster="local"``: a private Ray instance on this machine (``num_cpus`` = ``workers``, or every
  core), bound to 127.0.0.1, stopped at the end (:mod:`dlovr.batch.on_ray`);
- ``cluster="HOST:PORT"`` (or ``"auto"``, ``"ray://HOST:PORT"``): joins a running Ray cluster
  (``ray start --head`` elsewhere); ``workers`` then caps the tasks in flight.

A signal (SIGINT, SIGTERM) ends the batch: the workers are stopped (SIGTERM first, so that a task
writing a recording finishes it), and the exception carries the results finished so far
(:func:`finished`), for the caller to write. Workers also end when this process dies.

If this process is already connected to Ray (``ray.is_initialized()``), any ``cluster`` uses that
connection and leaves it open; :func:`cluster_session` holds one connection over several batches (a
private ``local`` instance is started once). Ray is imported only when a cluster is asked for.

Same seeds, same results: the engine adds no randomness and passes each task its own arguments, so a
task's value depends on its arguments only, not on where it ran. A task whose worker died is run again
(at most ``retries`` more times) and reported; a task that raises is not run again (its error is its
result). Every task yields exactly one result. Files a task writes land where the task writes them:
with a remote cluster, inputs and outputs must be on storage every node sees under the same paths
(docs/scaling.md).

Modules: :mod:`dlovr.batch.core` (tasks, results, bookkeeping), :mod:`dlovr.batch.local` (this
process, worker processes), :mod:`dlovr.batch.on_ray` (Ray).
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Callable, Generator, Iterator, Sequence
from typing import Any, cast

import click

from dlovr.batch.core import (
    INSTALL_HINT,
    BatchError,
    BatchSummary,
    Task,
    TaskResult,
    check_cluster,
    ray_installed,
    summarize,
)
from dlovr.batch.local import run_here, run_on_processes

__all__ = [
    "INSTALL_HINT",
    "BatchError",
    "BatchSummary",
    "Task",
    "TaskResult",
    "check_cluster",
    "cluster_option",
    "cluster_session",
    "finished",
    "ray_installed",
    "run_batch",
    "summarize",
]

log = logging.getLogger(__name__)


def run_batch(
    fn: Callable[..., Any],
    tasks: Sequence[Task],
    *,
    workers: int | None = None,
    cluster: str | None = None,
    retries: int = 2,
    progress: bool = True,
    label: str = "tasks",
) -> Iterator[TaskResult]:
    """Run ``fn`` over ``tasks``; yield each :class:`TaskResult` as it completes (see the module).

    ``fn`` must be importable by name (a module-level function) when it runs in other processes.
    ``progress`` draws a progress bar (``label``) on stderr and reports lost workers there (else they
    go to the ``dlovr.batch`` logger). Raises :class:`BatchError` when the cluster cannot be used.
    """
    tasks = list(tasks)
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        raise ValueError("task keys must be unique")
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    if retries < 0:
        raise ValueError(f"retries must be at least 0, got {retries}")
    check_cluster(cluster)
    note: Callable[[str], None] = (lambda msg: click.echo(f"\n{msg}", err=True)) if progress else log.warning
    inner: Generator[TaskResult, None, None]
    if cluster is not None:
        from dlovr.batch.on_ray import run_on_ray

        on_ray = run_on_ray(fn, tasks, workers, cluster, retries, note)
        next(on_ray)  # connected: a cluster that cannot be used fails here, before the progress bar
        inner = cast("Generator[TaskResult, None, None]", on_ray)  # only results follow the first None
    elif (workers or 1) == 1 or len(tasks) <= 1:
        inner = run_here(fn, tasks)
    else:
        inner = run_on_processes(fn, tasks, min(workers or 1, len(tasks)), retries, note)
    done: list[TaskResult] = []
    try:
        if not progress:
            for r in inner:
                done.append(r)
                yield r
            return
        with click.progressbar(length=len(tasks), label=label, file=sys.stderr, show_eta=True) as bar:
            for r in inner:
                bar.update(1)
                done.append(r)
                yield r
    except (KeyboardInterrupt, SystemExit) as e:  # a signal: the results so far go with it
        setattr(e, FINISHED, list(done))
        raise
    finally:
        inner.close()


@contextlib.contextmanager
def cluster_session(cluster: str | None, workers: int | None = None) -> Iterator[None]:
    """Within the block, every :func:`run_batch` on ``cluster`` uses one connection to Ray, made here
    (a ``local`` instance with ``workers`` CPUs, or the cluster at an address) and closed at the end,
    instead of one per batch. Nothing to do when ``cluster`` is None or Ray is already connected.
    Raises :class:`BatchError` when the cluster cannot be used."""
    if cluster is None:
        yield
        return
    check_cluster(cluster)
    from dlovr.batch.on_ray import ray_session

    with ray_session(cluster, workers):
        yield


#: The attribute of the ``KeyboardInterrupt`` or ``SystemExit`` (a signal) that ends a batch: the
#: :class:`TaskResult` of every task finished before it, in order of completion (:func:`finished`).
FINISHED = "dlovr_batch_finished"


def finished(e: BaseException) -> list[TaskResult]:
    """The results a batch had yielded when ``e`` (a signal's exception) ended it; [] if none."""
    return list(getattr(e, FINISHED, []))


def _cluster_callback(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    return check_cluster(value)


def cluster_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """The ``--cluster local|ADDRESS`` option of a batch command (passes ``cluster``: None when not
    given); a bad value or a missing Ray is one line, exit code 2."""
    return click.option(
        "--cluster",
        metavar="local|ADDRESS",
        callback=_cluster_callback,
        help="Run on Ray: 'local' starts a Ray instance here, HOST:PORT joins a running cluster "
        "(needs dlovr[ray]; outputs must be on storage every node sees). Default: local processes.",
    )(f)
