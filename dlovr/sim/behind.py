"""Contact tracking on a thread of its own, behind the simulation.

``mujoco.mj_step`` releases Python's global interpreter lock, so while the simulator steps on one
core, the contact tracker (:class:`dlovr.sim.tracker.ContactTracker`, Python) can work through the
steps already taken on another. :func:`tracking_behind` has the simulator hand every step's record to
a :class:`TrackingThread` instead of tracking it at once: the simulation's throughput (steps per
second of wall time) then stays near an untracked simulator's where a second core is free, and the
tracker's results are the same, bit for bit (it sees the same records, in the same order)::

    with tracking_behind(sim):
        for rec in sim.run(script):
            ...                      # rec.state is None here
    sim.tracker.changes              # every step tracked

What it costs: the records carry no ``state`` while it runs, and ``tracker.current``, ``changes``
and ``kept`` are complete only once the thread is closed. So it is for runs that read the contact
states at the end (``dlovr replay``), not for those that act on them step by step (the executor,
the browser).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

#: Steps handed to the thread at a time: one hand-over (a wake-up of the thread) per batch, not per step
#: (replaying peg-in-hole at 40 segments, 16, 64, 256 and 1,024 came within the rounds' noise of each
#: other, 64 and up about 0.01 of bare ``mj_step``'s throughput above 16).
BATCH = 64


class TrackingThread:
    """Runs ``tracker`` (a :class:`dlovr.sim.tracker.ContactTracker`) on a thread of its own, on the
    records :meth:`push` hands it, in order.

    The thread gives the interpreter lock back after every step (``time.sleep(0)``), so that the
    simulating thread, coming back from ``mj_step``, waits for at most one step's tracking.
    :meth:`close` waits until every pushed step is tracked and raises what the tracker raised (a
    tracker error also fails the next :meth:`push`); :meth:`stop` drops what is not yet tracked.
    """

    def __init__(self, tracker: Any, batch: int = BATCH) -> None:
        if batch < 1:
            raise ValueError(f"batch must be >= 1, got {batch}")
        self.tracker = tracker
        self.batch = batch
        self.error: BaseException | None = None
        self._todo: list[tuple[Any, tuple[Any, Any, Any]]] = []
        self._queue: queue.SimpleQueue[list[tuple[Any, tuple[Any, Any, Any]]] | None] = queue.SimpleQueue()
        self._stopped = False
        self._thread = threading.Thread(target=self._work, name="dlovr-tracking", daemon=True)
        self._thread.start()

    def push(self, record: Any, poses: tuple[Any, Any, Any]) -> None:
        """Track ``record`` (a :class:`dlovr.sim.StepRecord`) after those pushed before; ``poses``: its
        gripper position, quaternion and force as tuples of floats (what the simulator made of it)."""
        if self.error is not None:
            raise self.error
        todo = self._todo
        todo.append((record, poses))
        if len(todo) >= self.batch:
            self._queue.put(todo)
            self._todo = []

    def close(self) -> None:
        """Wait until every pushed step is tracked; raise the tracker's error if it raised one."""
        if self._todo:
            self._queue.put(self._todo)
            self._todo = []
        self._queue.put(None)
        self._thread.join()
        if self.error is not None:
            raise self.error

    def stop(self) -> None:
        """End the thread without tracking the steps still waiting (the run ended with an error)."""
        self._stopped = True
        self._todo = []
        self._queue.put(None)
        self._thread.join()

    def _work(self) -> None:
        state, nap, get = self.tracker._state, time.sleep, self._queue.get
        while True:
            batch = get()
            if batch is None:
                return
            for rec, poses in batch:
                if self._stopped:
                    return
                ca = rec.contact_arrays
                try:  # as Simulator.step calls it inline
                    state(rec, rec.step, rec.time, rec.points, ca.table, ca, poses, True)
                except BaseException as e:  # handed to the simulating thread (push, close)
                    self.error = e
                    return
                nap(0)  # the lock back to the simulating thread, if it waits


@contextmanager
def tracking_behind(sim: Any) -> Iterator[TrackingThread]:
    """Within the block, ``sim.tracker`` (a :class:`dlovr.sim.Simulator` made with ``track=True``)
    works on a thread of its own: each ``sim.step()`` hands it its record (``sim.behind``) instead of
    tracking it at once, so the two run side by side on two cores. The records carry no ``state``
    then, and the tracker's ``current``, ``changes`` and ``kept`` are complete, and the same bit for
    bit, once the block is left; an error of the tracker is raised by a later step or on leaving, and
    an error in the block drops the steps not yet tracked. Do not use the tracker inside the block."""
    if sim.tracker is None:
        raise ValueError("tracking behind needs Simulator(track=True)")
    if sim.behind is not None:
        raise RuntimeError("the simulator is tracking behind already")
    thread = sim.behind = TrackingThread(sim.tracker)
    try:
        yield thread
    except BaseException:
        sim.behind = None
        thread.stop()
        raise
    sim.behind = None
    thread.close()
