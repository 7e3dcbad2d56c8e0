"""A program's execution advanced step by step by its caller (the browser UI's real-time loop).

:func:`dlovr.execution.executor.execute` is one blocking loop over the simulation steps.
:class:`SteppedExecution` runs it unchanged in a worker thread that takes a simulation step only when
the caller grants one (:meth:`SteppedExecution.advance`), so the caller decides when the simulation
moves: the worker and the caller never touch the simulator at the same time, and the result is the
same as that of :func:`~dlovr.execution.executor.execute` (the same steps in the same order).

Beside the run it mirrors the detectors of the current macro (:mod:`dlovr.model.detection`, the
program's parameters, the executor's sensor chain: same noise seed and filter) to expose their
``signal`` for display: 1 is the threshold at which a detector fires.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from dlovr.execution.executor import DemoTrack, Event, ExecOptions, Execution, execute, expectation
from dlovr.execution.programs import MacroSpec, ProgramSpec
from dlovr.model.detection import Detector, NoiseModel, WrenchConditioner, make_detector


class Cancelled(Exception):
    """Raised inside the worker when the run is cancelled (never escapes :class:`SteppedExecution`)."""


class SteppedExecution:
    """``execute(program, sim, opts, track=...)`` advanced by :meth:`advance`.

    ``on_step(record)`` and ``on_event(event)`` are called in the worker thread while the caller waits
    in :meth:`advance`. After the run, ``done`` is true and ``execution`` holds the raw
    :class:`~dlovr.execution.executor.Execution` (None when it was cancelled or raised: ``error``).
    ``signal``: the current macro's detector signal (max over its classes; 1 = fires), ``macro`` the
    index of the macro running (0 before the first, and during the final motion its index).
    """

    def __init__(
        self,
        program: ProgramSpec,
        sim: Any,
        opts: ExecOptions | None = None,
        *,
        track: DemoTrack | None = None,
        on_step: Callable[[Any], None] | None = None,
        on_event: Callable[[Event], None] | None = None,
    ) -> None:
        opts = opts if opts is not None else ExecOptions()
        self.program, self.sim, self.opts, self.track = program, sim, opts, track
        self._on_step, self._on_event = on_step, on_event
        self._cv = threading.Condition()
        self._budget = 0
        self._taken = 0
        self._cancel = False
        self.done = False
        self.execution: Execution | None = None
        self.error: str | None = None
        self.events: list[Event] = []
        self.macro = 0
        self.signal = 0.0
        self._macros = {m.index: m for m in program.macros}
        self._detectors: list[Detector] = []
        self._cond = WrenchConditioner(NoiseModel(opts.noise, seed=opts.seed), opts.filter_tau)
        self._dt = float(sim.model.opt.timestep)
        self._f = self._tq = np.zeros(3)
        self._thread = threading.Thread(target=self._work, name="dlovr-execute", daemon=True)
        self._thread.start()

    # -- the caller's side ---------------------------------------------------------------------

    def advance(self, n: int) -> int:
        """Let the executor take up to ``n`` simulation steps and wait until it has (or the run
        ended); the number of steps taken."""
        with self._cv:
            if self.done or n <= 0:
                return 0
            before = self._taken
            self._budget = n
            self._cv.notify_all()
            self._cv.wait_for(lambda: self._budget == 0 or self.done)
            self._budget = 0
            return self._taken - before

    def cancel(self) -> None:
        """Stop the run at its next step and wait for the worker to end."""
        with self._cv:
            self._cancel = True
            self._cv.notify_all()
        self._thread.join(timeout=10)

    # -- the worker's side ---------------------------------------------------------------------

    def _wait_grant(self) -> None:
        with self._cv:
            self._cv.notify_all()
            self._cv.wait_for(lambda: self._budget > 0 or self._cancel)
            if self._cancel:
                raise Cancelled

    def _work(self) -> None:
        try:
            self._wait_grant()
            rec = self.sim.record()
            self._f, self._tq = self._cond(rec.gripper_force, _torque(rec), self._dt)
            self.execution = execute(
                self.program, self.sim, self.opts, track=self.track, on_step=self._step, on_event=self._event
            )
        except Cancelled:
            self.error = "cancelled"
        except Exception as e:  # reported by the caller, never lost in the thread
            self.error = f"{type(e).__name__}: {e}"
        finally:
            with self._cv:
                self.done = True
                self._cv.notify_all()

    def _step(self, record: Any) -> None:
        """After each executor step: mirror the detectors, report, then wait for the next grant."""
        self._f, self._tq = self._cond(record.gripper_force, _torque(record), self._dt)
        t = float(record.time)
        if self._detectors:
            for d in self._detectors:
                d.update(t, self._f, self._tq)
            self.signal = max(d.signal for d in self._detectors)
        if self._on_step is not None:
            self._on_step(record)
        with self._cv:
            self._taken += 1
            self._budget -= 1
            if self._budget > 0 and not self._cancel:
                return
        self._wait_grant()

    def _event(self, ev: Event) -> None:
        self.events.append(ev)
        if ev.kind in ("macro", "final"):
            self.macro = ev.macro
            m = self._macros.get(ev.macro)
            self._detectors = _detectors(m, self.opts, 1.0 / self._dt) if ev.kind == "macro" and m else []
            for d in self._detectors:
                d.start(float(self.sim.time), self._f, self._tq)
            self.signal = 0.0
        if self._on_event is not None:
            self._on_event(ev)


def _torque(record: Any) -> np.ndarray:
    return getattr(record, "gripper_torque", np.zeros(3))


def _detectors(m: MacroSpec, opts: ExecOptions, rate_hz: float) -> list[Detector]:
    if opts.detect != "force":
        return []
    exp = expectation(m)
    return [make_detector(d.cls, d.params, exp, rate_hz) for d in m.detection]
