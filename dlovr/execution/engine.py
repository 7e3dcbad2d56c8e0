"""The one execution engine: a compiled program or a network program run in a simulation, advanced
step by step by its caller.

:class:`Engine` has a public stepping API: :meth:`~Engine.start`, :meth:`~Engine.step` (one
simulation step), :attr:`~Engine.done` and :meth:`~Engine.result`. ``dlovr run`` and the trials run
it to its end (:meth:`Engine.run`, :func:`execute`); the browser's real-time loop grants it its steps
(:meth:`Engine.advance`) and shows the running macro's detector signal (:attr:`Engine.signal`). The
steps are those of :func:`dlovr.execution.executor.program_steps` for a
:class:`dlovr.model.program.Program` and of :func:`dlovr.execution.network_run.network_steps` for a
:class:`dlovr.model.planning.NetworkProgram`: the same steps in the same order however it is
advanced.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from dlovr.execution.demo_track import DemoTrack
from dlovr.execution.executor import Event, ExecOptions, Execution, Session, Steps, program_steps
from dlovr.execution.network_run import NetworkOptions, NetworkRunResult, format_network_result, network_steps
from dlovr.execution.recovery import Recovery, recovering_steps
from dlovr.execution.scoring import RunResult, score
from dlovr.execution.scoring import format_result as format_program_result
from dlovr.model.planning import NetworkProgram
from dlovr.model.program import Program, Runnable


class Engine:
    """One run of ``program`` in ``sim`` (a :class:`dlovr.sim.Simulator` with ``track=True``, at its
    start pose).

    ``opts``: how macros run; ``track``: the demonstration's gripper trajectory a compiled program's
    macros follow (:func:`dlovr.execution.executor.program_steps`); ``scene``: the ``dlovr.scene.Scene``
    simulated (its name goes into the result; a network program needs it for the cable's weight);
    ``network``: a network program's options. ``on_step(record)`` sees every step, ``on_event(event)``
    every :class:`dlovr.execution.executor.Event`. ``recovery``: a compiled program that misses its
    goal plans again through this network (:mod:`dlovr.execution.recovery`). A diverged simulation
    ends the run with its reason in the result (never raises).
    """

    def __init__(
        self,
        program: Runnable,
        sim: Any,
        opts: ExecOptions | None = None,
        *,
        track: DemoTrack | None = None,
        scene: Any = None,
        network: NetworkOptions | None = None,
        on_step: Callable[[Any], None] | None = None,
        on_event: Callable[[Event], None] | None = None,
        recovery: Recovery | None = None,
    ) -> None:
        self.program, self.sim, self.track, self.scene = program, sim, smoothed(program, track), scene
        self.recovery = recovery
        self.opts = opts if opts is not None else ExecOptions()
        self.network = network if network is not None else NetworkOptions()
        self._on_step, self._on_event = on_step, on_event
        self.session: Session | None = None
        #: the raw outcome of a compiled program's run (judged by :func:`dlovr.execution.scoring.score`)
        self.execution: Execution | None = None
        self.error: str | None = None
        self._steps: Steps[Any] | None = None
        self._result: NetworkRunResult | None = None
        self._done = False
        self._wall0 = 0.0

    def start(self) -> None:
        """Set up the sensor chain and the run (no simulation step yet)."""
        self._steps = self._begin()

    def _begin(self) -> Steps[Any]:
        self._wall0 = time.perf_counter()
        ses = self.session = Session(self.sim, self.opts, on_step=self._on_step, on_event=self._on_event)
        if isinstance(self.program, Program):  # the one place where programs and networks part
            self.execution = Execution(self.program, self.opts, events=ses.events)
            if self.recovery is not None:
                scene = self.scene if self.scene is not None else getattr(self.sim, "scene", None)
                return recovering_steps(self.program, ses, self.execution, self.track, self.recovery, scene)
            return program_steps(self.program, ses, self.execution, self.track)
        if isinstance(self.program, NetworkProgram):
            return network_steps(self.program, ses, self.scene, self.network)
        raise TypeError(f"cannot run a {type(self.program).__name__}")

    def step(self) -> bool:
        """Take one simulation step: True when it did, False when the run ended instead (``done``)."""
        if self._done:
            return False
        steps = self._steps
        if steps is None:
            steps = self._steps = self._begin()
        try:
            next(steps)
            return True
        except StopIteration as stop:
            self._finish(stop.value)
            return False

    @property
    def done(self) -> bool:
        return self._done

    def result(self) -> RunResult | NetworkRunResult:
        """The judged run (after :attr:`done`): a :class:`dlovr.execution.scoring.RunResult` for a
        compiled program, a :class:`dlovr.execution.network_run.NetworkRunResult` for a network one."""
        if self._result is not None:
            return self._result
        if self.execution is None:
            raise RuntimeError(f"the run did not end with a result: {self.error or 'not run'}")
        return score(self.execution, self.scene.name if self.scene is not None else "")

    def run(self) -> RunResult | NetworkRunResult:
        """Every step to the end; the judged run."""
        while self.step():
            pass
        return self.result()

    # -- what the browser's real-time loop uses --------------------------------------------------

    def advance(self, n: int) -> int:
        """Up to ``n`` steps; how many were taken. An exception ends the run with ``error`` set and
        no result (the caller's loop goes on)."""
        taken = 0
        try:
            while taken < n and self.step():
                taken += 1
        except Exception as e:  # reported by the caller, never lost in its loop
            self._fail(f"{type(e).__name__}: {e}")
        return taken

    def cancel(self) -> None:
        """Stop the run where it is (no result)."""
        if not self._done:
            self._fail("cancelled")

    @property
    def events(self) -> list[Event]:
        return self.session.events if self.session is not None else []

    @property
    def macro(self) -> int:
        """The index of the macro running (0 before the first; the final motion's during it)."""
        return self.session.macro if self.session is not None else 0

    @property
    def signal(self) -> float:
        """The running macro's force detector signal (max over its classes; 1 = fires)."""
        return self.session.signal if self.session is not None else 0.0

    def _finish(self, value: NetworkRunResult | None) -> None:
        self._done, self._result = True, value
        if self.execution is not None:
            self.execution.wall_time = time.perf_counter() - self._wall0

    def _fail(self, why: str) -> None:
        if self._steps is not None:
            self._steps.close()
        self._done, self.error, self.execution = True, why, None


def format_result(res: RunResult | NetworkRunResult) -> str:
    """The per-macro table and the result line of a run, as ``dlovr run`` prints them."""
    if isinstance(res, NetworkRunResult):
        return format_network_result(res)
    return format_program_result(res)


def execute(
    program: Program,
    sim: Any,
    opts: ExecOptions | None = None,
    *,
    track: DemoTrack | None = None,
    on_step: Callable[[Any], None] | None = None,
    on_event: Callable[[Event], None] | None = None,
) -> Execution:
    """Run ``program`` in ``sim`` to its end and return the raw
    :class:`dlovr.execution.executor.Execution` (judge it with :func:`dlovr.execution.scoring.score`).

    ``track``: the demonstration's gripper trajectory; when given, each macro follows its recorded
    stretch of it (:class:`dlovr.execution.motion.TrackPath`) instead of the screw between the
    demonstrated poses, and a program without a final macro ends with the rest of the recording.
    """
    eng = Engine(program, sim, opts, track=track, on_step=on_step, on_event=on_event)
    while eng.step():
        pass
    if eng.execution is None:
        raise RuntimeError(f"the run ended without an outcome: {eng.error}")
    return eng.execution


def follows_hand(program: Runnable, track: DemoTrack | None) -> bool:
    """Whether ``program`` runs along a hand's track: ``track`` given and the program compiled
    smoothed (``Program.smoothing_s``), so that :func:`smoothed` makes it ``by_hand``."""
    return track is not None and bool(getattr(program, "smoothing_s", 0.0))


def smoothed(program: Runnable, track: DemoTrack | None) -> DemoTrack | None:
    """The track a compiled program follows: its demonstration's, smoothed as the program was
    compiled (``Program.smoothing_s``: a trembling hand's track; :mod:`dlovr.model.smoothing`)."""
    if track is None or not follows_hand(program, track):
        return track
    window = getattr(program, "smoothing_s", 0.0)
    from dlovr.model.smoothing import smooth_poses

    pos, quat = smooth_poses(track.t, track.pos, track.quat, window)
    # its sensed wrench and forces are the demonstration's
    return replace(track, pos=pos, quat=quat, by_hand=True)
