"""Batch work on Ray: a private instance on this machine (``local``) or a running cluster (an address).

Imported only when a cluster is asked for; Ray itself is imported here, inside :func:`run_on_ray`.
Tasks run as Ray tasks of one CPU each with Ray's own retries off: a task whose worker died
(``WorkerCrashedError``, a lost node or object) is submitted again here, so that its attempts are
counted and reported the same way as on local processes.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
from collections import deque
from collections.abc import Callable, Generator, Iterator, Sequence
from typing import Any

from dlovr.batch.core import (
    INSTALL_HINT,
    Attempts,
    BatchError,
    Task,
    TaskResult,
    call_task,
    host_port,
    one_line,
)

# Ray's switch that makes a node use the loopback address (its default on macOS and Windows)
_LOOPBACK_ENV = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
# Ray's authentication mode; a cluster with token authentication (Ray's default for a new one when
# a token exists) refuses a driver that joins by address without it
_AUTH_ENV = "RAY_AUTH_MODE"
_AUTH_HINT = (
    "; if the cluster uses token authentication, set RAY_AUTH_MODE=token and its token "
    "(RAY_AUTH_TOKEN or ~/.ray/auth_token) here (docs/scaling.md)"
)


def _first_sentence(e: BaseException) -> str:
    """``Type: first sentence`` of one of Ray's (long) errors."""
    text = one_line(e)
    return text.split(". ", 1)[0].rstrip(".")


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise BatchError(f"--cluster needs Ray, which is not installed: {INSTALL_HINT}") from None
    return ray


@contextlib.contextmanager
def _loopback_only(ray: Any) -> Iterator[None]:
    """While starting a local instance: make Ray bind its servers to 127.0.0.1 only."""
    saved_env = os.environ.get(_LOOPBACK_ENV)
    os.environ[_LOOPBACK_ENV] = "0"
    constants = getattr(getattr(ray, "_private", None), "ray_constants", None)
    saved = getattr(constants, "ENABLE_RAY_CLUSTER", None)
    if constants is not None and saved is not None:
        constants.ENABLE_RAY_CLUSTER = False
    try:
        yield
    finally:
        if constants is not None and saved is not None:
            constants.ENABLE_RAY_CLUSTER = saved
        if saved_env is None:
            os.environ.pop(_LOOPBACK_ENV, None)
        else:
            os.environ[_LOOPBACK_ENV] = saved_env


def connect(ray: Any, cluster: str, workers: int | None) -> bool:
    """Start a local instance or join the cluster at ``cluster``; False if already connected."""
    if ray.is_initialized():
        return False
    quiet: dict[str, Any] = {"log_to_driver": False, "logging_level": logging.ERROR}
    if cluster == "local":
        with _loopback_only(ray):
            try:
                ray.init(num_cpus=workers or os.cpu_count() or 1, include_dashboard=False, **quiet)
            except (RuntimeError, ConnectionError, OSError, ValueError) as e:
                raise BatchError(f"cannot start a local Ray instance: {one_line(e)}") from None
        return True
    hp = host_port(cluster)
    if hp is not None:
        try:
            socket.create_connection(hp, timeout=5.0).close()
        except OSError as e:
            raise BatchError(f"cannot reach the Ray cluster at {cluster}: {e.strerror or e}") from None
    try:
        ray.init(address=cluster, **quiet)
    except (RuntimeError, ConnectionError, OSError, ValueError) as e:
        # Ray never enables token authentication by itself when given an address: say how
        hint = "" if os.environ.get(_AUTH_ENV, "").lower() == "token" else _AUTH_HINT
        raise BatchError(f"cannot join the Ray cluster at {cluster}: {one_line(e)}{hint}") from None
    return True


@contextlib.contextmanager
def ray_session(cluster: str, workers: int | None) -> Iterator[None]:
    """Connected to Ray for the whole block (see :func:`dlovr.batch.cluster_session`)."""
    ray = _import_ray()
    own = connect(ray, cluster, workers)
    try:
        yield
    finally:
        if own:
            ray.shutdown()


def run_on_ray(
    fn: Callable[..., Any],
    tasks: Sequence[Task],
    workers: int | None,
    cluster: str,
    retries: int,
    note: Callable[[str], None],
) -> Generator[TaskResult | None, None, None]:
    """Run the tasks as Ray tasks: first yield None once connected (so that a cluster that cannot be
    used fails before any progress is drawn), then the results in order of completion.

    ``workers`` caps the tasks in flight (and sets a local instance's CPUs). A task whose worker or
    node was lost is submitted again, at most ``retries`` more times; ``note`` gets a line for each.
    """
    ray = _import_ray()
    own = connect(ray, cluster, workers)
    try:
        yield None
    except GeneratorExit:
        if own:
            ray.shutdown()
        raise
    remote = ray.remote(num_cpus=1, max_retries=0)(call_task)
    book = Attempts(tasks, retries, note)
    queue = deque(range(len(tasks)))
    limit = workers or len(tasks)
    in_flight: dict[Any, int] = {}
    clean = False
    try:
        while queue or in_flight:
            while queue and len(in_flight) < limit:
                i = queue.popleft()
                book.count[i] += 1
                in_flight[remote.remote(fn, tasks[i].args, dict(tasks[i].kwargs))] = i
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            for ref in ready:
                i = in_flight.pop(ref)
                try:
                    out = ray.get(ref)
                except ray.exceptions.RayTaskError as e:  # the wrapper itself failed (e.g. pickling)
                    yield book.result(i, False, one_line(e.cause or e), "")
                except ray.exceptions.RayError as e:  # the worker or its node was lost
                    failed = book.worker_lost(i, _first_sentence(e))
                    if failed is None:
                        queue.appendleft(i)
                    else:
                        yield failed
                else:
                    yield book.result(i, *out)
        clean = True
    finally:
        if not clean and not own:
            for ref in in_flight:
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)
        if own:
            ray.shutdown()
