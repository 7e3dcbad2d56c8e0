"""Executing a program in simulation: each macro a force-guarded motion (docs/model.md, paper §VI).

Per macro, the gripper repeats the demonstrated motion (:class:`dlovr.execution.motion.ScrewPath`)
from where the previous macro ended, at the demonstrated pace but no faster than ``max_speed``
(m/s) and ``max_angular_speed`` (rad/s), while the detector of the macro's class
(:mod:`dlovr.model.detection`) watches the gripper's wrench -- the only sensor: the executor never
reads the contact model. The macro ends when the detector fires; it fails when the motion reaches
its allowance (``allowance`` times the demonstrated motion, 1.5 by default) and the transition is
still not detected ``settle`` seconds later. The program stops at the first failure.

``detect="oracle"`` ends each macro instead when the contact tracker sees the expected change of
principal contacts (to tell program errors from detection errors). Either way the tracker's debounced
situations are logged beside the run to judge it afterwards (:mod:`dlovr.execution.scoring`).

Every part of a run here is a generator of simulation steps (:data:`Steps`: it yields after each step
and returns its outcome): :func:`program_steps` for a whole program, :func:`run_macro` and
:func:`run_final` for one macro, :meth:`Session.hold`. The execution engine
(:class:`dlovr.execution.engine.Engine`) advances them one step at a time, and network programs
(:mod:`dlovr.execution.network_run`) are made of the same parts.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar, cast

import numpy as np

from dlovr.execution.demo_track import DemoTrack
from dlovr.execution.motion import (
    HAND_EASE_S,
    Quat,
    ScrewPath,
    ShiftedPath,
    TrackPath,
    TurnedPath,
    Vec,
    eased,
    hand_path,
    last_start,
    local_twist,
    tip_offset,
    touches_tip,
)
from dlovr.model.derivation import (
    FREE_WINDOW_S,
    GOAL_MIN_CONTACT_N,
    GOAL_MIN_TOLERANCE_DEG,
    GOAL_SENSE_S,
)
from dlovr.model.detection import (
    DEFAULT_FILTER_TAU_S,
    MIN_SNR,
    Detector,
    Expectation,
    NoiseModel,
    WrenchConditioner,
    for_sensor,
    make_detector,
    no_force_signal,
)
from dlovr.model.program import Macro, Program
from dlovr.model.transitions import principal, successional_contacts
from dlovr.transforms import angle_deg, dot, norm, quat_mul, quat_normalize, quat_rotate, slerp

T = TypeVar("T")
#: A run's work between two simulation steps: a generator that yields after each step and returns
#: its outcome (the engine, :mod:`dlovr.execution.engine`, advances it one step at a time).
Steps = Generator[None, None, T]

DETECT_MODES = ("force", "oracle")
#: How a macro may end and the program go on: its transition detected, or -- a macro whose
#: demonstration shows no force signal for its transition (threshold not below the demonstrated
#: step, see :mod:`dlovr.model.derivation`) -- its demonstrated motion completed; or, following a
#: hand's track, its transition not felt within the allowance (``"went on"``, :func:`run_macro`).
ENDED_OK = ("detected", "motion", "went on")

#: Time (s) the gripper holds its last pose after a program (or a replay) before the goal is judged: a
#: soft, high-friction cable still creeps into place after the motion stops (a tip sliding into a
#: corner goes on at a few mm/s for a second), and the goal is a situation the cable rests in.
FINAL_SETTLE_S = 2.0

#: How much of the sensed force (s) a session keeps to settle a detector's own smoothing at its start.
HISTORY_S = 0.3

#: How far (m) a program's start may lie from the scene's gripper pose, and by what angle (deg).
START_TOL_M = 0.02
START_TOL_DEG = 10.0
#: Gravity (m/s^2): the cable's weight the robot knows (its payload).
GRAVITY = 9.81


@dataclass(frozen=True)
class ExecOptions:
    """How a program is executed.

    ``noise``: standard deviation (N) of the Gaussian force noise (torque: see
    :class:`dlovr.model.detection.NoiseModel`), drawn from ``seed``; ``filter_tau`` (s) the
    detectors' low-pass filter; ``allowance``: how far the motion may go, as a multiple of the
    demonstrated one; ``settle`` (s): how long to wait at the end of the allowance; ``min_duration``
    (s): the shortest time a macro's demonstrated motion is repeated in; ``final_settle`` (s): time
    the gripper holds its last pose after the last macro before the goal is judged
    (:data:`FINAL_SETTLE_S`); ``frame``: ``world`` or ``relative``
    (see :mod:`dlovr.execution.motion`), unless a macro names its own; ``oracle_hold`` (s): how long
    the oracle wants the expected contacts before it ends a macro; ``start_settle`` (s): the gripper
    holds its start pose this long before the first macro (default none: the demonstrations start
    moving at once, and a settled cable repeats some of their dynamic transitions differently).
    ``blank`` (s): the force detectors take their reference this long after a macro starts (the
    wrench still rings from the transition that ended the previous macro); ``arm``: they may fire
    only once the motion has covered this fraction of the demonstrated one (a transition that
    happened earlier and holds is detected then; a passing swing is not). Neither applies to the
    oracle. ``bounce`` (s): a demonstrated transition undone by the next one within this time (the
    cable bouncing off and back: a dynamic accident of the demonstration) is not waited for: both
    macros end by their motion (the oracle's too: the bounce need not repeat). ``phase_blank`` (s):
    following the recorded track, the force detectors are armed this long into the stretch's last
    motion phase (where the gripper last set off after holding still), since the transition came in
    it and the gripper starting or stopping earlier shakes the wrench. ``min_snr``: a detection whose
    demonstrated step is less than this many times the noise before it (a gradual change) ends its
    macro by motion, as one whose threshold is not below its step does. ``sensor_noise`` (N): the
    white noise the detectors assume of the sensor (:func:`dlovr.model.detection.for_sensor`: their
    smoothing and threshold floors); ``None``: the simulated ``noise`` (a robot knows its sensor).
    ``give_way`` (m): an ``E`` transition that slides the cable along a face into its new contact
    moves this far away from that face over its motion (:func:`dlovr.execution.motion.given_way`;
    blind, a face a few mm nearer than demonstrated presses the sliding cable, which sticks, bends and
    shakes the wrench like the transition); 0: as demonstrated; ``None`` (default): by who made the
    track followed (:func:`dlovr.execution.motion.give_way_m`: 5 mm for a hand's, whose drift may
    have pressed the slide onto its face; 0 for a script's).
    ``object_shifts``: (object name, shift m world) pairs, where the objects really are against the
    demonstration (a registered run, ``dlovr run --registered``; empty: blind): each macro moves in
    the frame of the object its principal contacts name (:mod:`dlovr.execution.motion`, "Frames of
    objects"). ``object_turns``: (object name, rotation wxyz world) pairs of the objects that are also
    turned (``R`` of the rigid motion ``p -> R p + t`` that takes the demonstration's object to the
    real one, ``t`` then its ``object_shifts`` entry): a registered run turns the program's start pose
    and its world-frame motions with them, expects its contact vectors turned, and checks the goal in
    their frame.
    """

    detect: str = "force"
    noise: float = 0.0
    seed: int = 0
    filter_tau: float = DEFAULT_FILTER_TAU_S
    allowance: float = 1.5
    max_speed: float = 0.25
    max_angular_speed: float = 2.0
    min_duration: float = 0.1
    settle: float = 0.3
    final_settle: float = FINAL_SETTLE_S
    frame: str = "world"
    oracle_hold: float = 0.02
    start_settle: float = 0.0
    bounce: float = 0.1
    blank: float = 0.05
    arm: float = 0.5
    phase_blank: float = 0.15
    min_snr: float = MIN_SNR
    sensor_noise: float | None = None
    give_way: float | None = None
    object_shifts: tuple[tuple[str, tuple[float, float, float]], ...] = ()
    object_turns: tuple[tuple[str, tuple[float, float, float, float]], ...] = ()

    def __post_init__(self) -> None:
        if self.detect not in DETECT_MODES:
            raise ValueError(f"detect must be one of {', '.join(DETECT_MODES)}, got {self.detect!r}")
        names = ("noise", "filter_tau", "settle", "final_settle", "min_duration", "oracle_hold", "blank",
                 "arm", "bounce", "phase_blank", "min_snr")
        for name in (*names, "start_settle"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")
        for name in ("allowance", "max_speed", "max_angular_speed"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        if self.allowance < 1.0:
            raise ValueError(f"allowance must be >= 1 (times the demonstrated motion), got {self.allowance}")
        if self.frame not in ("world", "relative"):
            raise ValueError(f"frame must be 'world' or 'relative', got {self.frame!r}")
        for name in ("sensor_noise", "give_way"):  # None: as the docstring says
            v = getattr(self, name)
            if v is not None and not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")

    @property
    def registered(self) -> bool:
        """Whether the executor is told where the objects are (``object_shifts``, ``object_turns``)."""
        return bool(self.object_shifts or self.object_turns)

    @property
    def assumed_noise(self) -> float:
        """The sensor's white noise (N) the detectors are set for: ``sensor_noise``, else ``noise``."""
        return self.noise if self.sensor_noise is None else self.sensor_noise


@dataclass(frozen=True)
class Event:
    """An executor event: ``kind`` one of ``start``, ``macro``, ``detected``, ``went_on`` (a hand's
    macro not felt within its allowance, :func:`run_macro`), ``failed``, ``final``, ``end``; ``t``
    simulated time (s); ``macro`` its index (0 for none); ``text`` what happened."""

    t: float
    step: int
    kind: str
    macro: int
    text: str

    def payload(self) -> dict[str, Any]:
        return {"t": self.t, "step": self.step, "kind": self.kind, "macro": self.macro, "text": self.text}


@dataclass(frozen=True)
class MacroRun:
    """What happened while one macro ran (times in s of simulated time, distances in m).

    ``ended``: ``detected``, ``allowance`` (the motion reached its allowance and nothing was
    detected), or ``diverged``; ``moved``/``allowed``: how far the gripper went and could go along
    the demonstrated motion (path parameter times the demonstrated distance; for a pure rotation,
    radians).
    """

    macro: Macro
    started_at: float
    ended_at: float
    ended: str
    detected_at: float | None
    moved: float
    allowed: float
    peak_signal: float
    reason: str = ""
    resume_at: float | None = None  # demonstration time (s) its motion reached, when short of its end


@dataclass(frozen=True)
class Replan:
    """One recovery of a compiled program through a transition network
    (:mod:`dlovr.execution.recovery`): after the sensed goal check did not confirm the goal, the
    situation sensed (``node``, its ``situation``; ``sensed`` the contact vector, world, unit or zero;
    ``node`` empty when none fitted), the network loop's path and whether it arrived at the goal node
    (``arrived``; ``reason`` why not), and the goal check after it (``goal_sensed``, ``goal_angle``
    deg). Times ``started_at``/``ended_at`` in s of simulated time."""

    node: str
    situation: str
    sensed: tuple[float, float, float] | None
    path: tuple[str, ...]
    arrived: bool
    reason: str
    goal_sensed: bool | None
    goal_angle: float | None
    started_at: float
    ended_at: float


@dataclass
class Execution:
    """The raw outcome of a program's run (:func:`dlovr.execution.engine.execute`): per-macro runs,
    the tracker's debounced situations (``kept``: list of ``dlovr.model.transitions.Kept``), the
    events and where it stopped; ``replans``: the recoveries through a network after the goal was
    missed (:mod:`dlovr.execution.recovery`)."""

    program: Program
    options: ExecOptions
    runs: list[MacroRun] = field(default_factory=list)
    events: list[Event] = field(default_factory=list)
    kept: list[Any] = field(default_factory=list)
    diverged: str | None = None
    sim_time: float = 0.0
    wall_time: float = 0.0
    final_done: bool = False
    goal_force: tuple[float, float, float] | None = None
    goal_torque: tuple[float, float, float] | None = None
    goal_sensed: bool | None = None
    goal_force_diff: float | None = None
    goal_angle: float | None = None
    replans: list[Replan] = field(default_factory=list)


def principal_states(situation: Any) -> tuple[str, ...]:
    """Principal contacts of a discrete situation as the program writes them (with faces), sorted."""
    return tuple(sorted(c.format() for run in successional_contacts(situation) for c in principal(run)))


def transition_seen(principals: tuple[str, ...], m: Macro) -> bool:
    """Whether a situation with these principal contacts shows the macro's transition: the principal
    contacts it begins are there and those it ends are gone (states and faces)."""
    have = set(principals)
    return all(c.state in have for c in m.established) and not any(c.state in have for c in m.released)


def expectation(m: Macro) -> Expectation:
    """What the macro's detectors expect: the contact vectors of the principal contacts its transition
    ends and begins, and the axes of those that are pinches (docs/model.md, Pinch)."""
    changing = (*m.released, *m.established)
    axes = tuple(c.axis for c in changing if c.axis is not None)
    return Expectation(tuple(c.vector for c in m.released), tuple(c.vector for c in m.established), axes)


def turned(exp: Expectation, turn: Quat) -> Expectation:
    """``exp`` with its vectors and axes turned by ``turn`` (wxyz, world): what a registered run
    expects of objects that are turned."""
    if tuple(turn) == (1.0, 0.0, 0.0, 0.0):
        return exp
    q = np.asarray(turn, float)

    def rot(v: Any) -> Any:
        return None if v is None else cast(Vec, tuple(float(x) for x in quat_rotate(q, np.asarray(v, float))))

    return Expectation(tuple(rot(v) for v in exp.released), tuple(rot(v) for v in exp.established),
                       tuple(rot(a) for a in exp.axes))


def pace(m: Macro, opts: ExecOptions) -> float:
    """Seconds for the demonstrated motion (s from 0 to 1): the demonstrated duration, but no
    faster than the speed bounds and no shorter than ``min_duration``."""
    mo = m.motion
    fastest = max(mo.distance / opts.max_speed, mo.angle / opts.max_angular_speed)
    return max(mo.duration, fastest, opts.min_duration)


class Guard:
    """The sensing side of one macro: the force detectors of its classes, or the oracle."""

    def __init__(self, m: Macro, opts: ExecOptions, rate_hz: float, turn: Quat = (1.0, 0.0, 0.0, 0.0)):
        self.macro = m
        self.oracle = opts.detect == "oracle"
        self.detectors: list[Detector] = []
        sigma = opts.assumed_noise
        params = [for_sensor(d.cls, d.params, sigma, 1.0 / rate_hz)[0] for d in m.detection]
        if not self.oracle:
            exp = turned(expectation(m), turn)
            pairs = zip(m.detection, params, strict=True)
            self.detectors = [make_detector(d.cls, p, exp, rate_hz) for d, p in pairs]
        self.peak = 0.0
        self.hold = opts.oracle_hold
        self._since: float | None = None
        #: every detection's threshold is at or above the demonstrated step (or too close to it for the
        #: sensor's noise): no force signal to watch
        self.weak = bool(m.detection) and all(
            no_force_signal(d.cls, p, opts.min_snr) for d, p in zip(m.detection, params, strict=True)
        )

    def start(
        self, t: float, f: np.ndarray, tq: np.ndarray, history: Sequence[tuple[float, np.ndarray]] = ()
    ) -> None:
        self._since = None
        for d in self.detectors:
            d.start(t, f, tq, history)

    def lag(self) -> float:
        """The delay (s) the fired detector's own smoothing (a noisy sensor) adds to a detection."""
        return max((d.smoothing_lag() for d in self.detectors if d.fired_at is not None), default=0.0)

    def update(self, t: float, f: np.ndarray, tq: np.ndarray, record: Any, armed: bool = True) -> bool:
        """Whether the transition is seen at ``t``; before ``armed`` a detector that fires is reset
        (keeping its reference), so it fires at arming only if its criterion still holds then."""
        if self.oracle:
            st = getattr(record, "state", None)
            if st is None or not transition_seen(principal_states(st.discrete), self.macro):
                self._since = None
                return False
            if self._since is None:
                self._since = t
            self.peak = max(self.peak, min(1.0, (t - self._since) / self.hold) if self.hold > 0 else 1.0)
            return t - self._since >= self.hold - 1e-9
        fired = False
        for d in self.detectors:
            hit = d.update(t, f, tq)
            if hit and not armed:
                d.fired_at, hit = None, False
            fired = hit or fired
            self.peak = max(self.peak, d.signal)
        return fired


#: The time (s) over which the sensed force at the end of a run (and of the demonstration) is
#: averaged (:data:`dlovr.model.derivation.GOAL_SENSE_S`); where a demonstration's cable hangs free and
#: settled, its weight sensed (s from its start; the first 0.2 s still ring from the start); an
#: environment share below :data:`GOAL_MIN_CONTACT_N` (N) is no contact (its direction not compared).
#: :data:`GOAL_ANGLE_DEG`: how far (degrees) the contact vector sensed at the end of a run may turn
#: from the one the demonstration sensed at its end for the goal to count as confirmed, where the
#: program gives no tolerance of its own (``Program.goal_tolerance_deg``, derived from the
#: demonstration's own spread in its goal: :func:`dlovr.model.derivation.goal_tolerance_deg`; this is
#: its floor). Measured on peg_in_hole: runs that reached the goal 0.5-3 deg, runs that ended with the
#: tip on the hole block's top 14-16 deg (docs/programs.md).
GOAL_ANGLE_DEG = GOAL_MIN_TOLERANCE_DEG


def goal_check(
    sensed: Sequence[float] | np.ndarray, track: DemoTrack | None, noise: float, n: int,
    weight: Sequence[float] | np.ndarray | None = None,
    demo_weight: Sequence[float] | np.ndarray | None = None,
    tolerance: float = GOAL_ANGLE_DEG,
) -> tuple[bool | None, float | None]:
    """Whether the force sensed at the end of a run (mean of ``n`` samples, N, world) confirms the
    goal, and the angle (deg) it is judged by.

    The **sensed contact vector** is the environment's share of the sensed force: the sensed force
    minus the cable's weight (``weight``, N world, as the robot knows its payload; default the
    demonstration's own, ``track.free_force``). It is compared with the one the demonstration sensed
    at its end (``track.end_force`` minus its cable's weight: ``demo_weight``, default
    ``track.free_force``, what it sensed while the cable hung free): within ``tolerance`` degrees
    (the program's own, else :data:`GOAL_ANGLE_DEG`; plus
    the angle of 4 standard deviations of the mean's noise, white ``noise`` N a sample) the goal's
    contacts push the cable as they did at the demonstration's end. Its size is not compared: a
    stiffer or longer cable presses harder into the same contacts. (None, None) without a
    demonstrated end force and free force, or where either share is below
    :data:`GOAL_MIN_CONTACT_N` (then the sizes are compared: both no contact confirms)."""
    demo_free = track.free_force if track is not None and demo_weight is None else demo_weight
    if track is None or track.end_force is None or demo_free is None or n <= 0:
        return None, None
    run = np.asarray(sensed, float) - np.asarray(demo_free if weight is None else weight, float)
    demo = np.asarray(track.end_force, float) - np.asarray(demo_free, float)
    a, b = norm(run.tolist()), norm(demo.tolist())
    if a < GOAL_MIN_CONTACT_N or b < GOAL_MIN_CONTACT_N:
        both_free = a < GOAL_MIN_CONTACT_N and b < GOAL_MIN_CONTACT_N
        return both_free, 0.0 if both_free else 90.0
    angle = angle_deg(run, demo)
    slack = math.degrees(math.atan(min(4.0 * noise / math.sqrt(n) / a, 1.0)))
    return angle <= tolerance + slack, angle


#: A record without a torque reads none (the sensor chain copies it, never writes it).
_NO_TORQUE = np.zeros(3)
_NO_TORQUE.flags.writeable = False


class Session:
    """One execution in progress: the simulator, the sensor chain, the event log and the guard of the
    macro running (whose detector signal the browser shows)."""

    def __init__(
        self, sim: Any, opts: ExecOptions, *, on_step: Callable[[Any], None] | None = None,
        on_event: Callable[[Event], None] | None = None,
    ) -> None:
        self.sim, self.opts = sim, opts
        self.on_step, self.on_event = on_step, on_event
        self.dt = float(sim.model.opt.timestep)
        self.events: list[Event] = []
        #: the macro running (its index; 0 before the first) and its guard (None in a final motion)
        self.macro = 0
        self.guard: Guard | None = None
        #: how much further the cable's tip is from the gripper than demonstrated (m, gripper frame),
        #: once the tip's first touch has been felt (:func:`tip_offset`); turns are repeated about it
        self.tool: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.tool_known = False
        #: the shift (m, world) of the objects the motion is in the frame of, as applied so far
        self.shift: Vec = (0.0, 0.0, 0.0)
        #: the turn (wxyz, world) of the objects the motion is in the frame of (registered runs)
        self.turn: Quat = IDENTITY
        #: a detection taken back by its latency (:func:`_detected`) leaves the gripper where it fired
        #: and keeps where it goes back to in ``back`` (position m, quaternion wxyz, world; the lag s):
        #: a network run senses the contact first, then goes back (``dlovr.execution.network_run``)
        self.sense_before_back = False
        self.back: tuple[Any, Any, float] | None = None
        self.cond = WrenchConditioner(NoiseModel(opts.noise, seed=opts.seed), opts.filter_tau)
        rec = sim.record()
        if sim.tracker is not None and sim.tracker.current is None:
            sim.tracker.restart(rec)
        self.f, self.tq = self.cond(rec.gripper_force, getattr(rec, "gripper_torque", _NO_TORQUE), self.dt)
        #: the sensed force of the last :data:`HISTORY_S` (time s, force N): settles a detector's own
        #: smoothing when it starts (kept only for a noisy sensor)
        self.recent: deque[tuple[float, np.ndarray]] = deque(maxlen=max(1, round(HISTORY_S / self.dt)))
        self._noisy = opts.assumed_noise > 0.0  # (kept only for a noisy sensor)

    @property
    def signal(self) -> float:
        """The running macro's force detector signal (max over its classes; 1 = fires; 0 without)."""
        dets = self.guard.detectors if self.guard is not None else []
        return max((d.signal for d in dets), default=0.0)

    def weight(self) -> np.ndarray | None:
        """The cable's weight (N, world: ``-m g`` along z) as the robot knows its payload, from the
        simulated scene (None without one)."""
        dlo = getattr(getattr(self.sim, "scene", None), "dlo", None)
        mass = getattr(dlo, "mass", None)
        return None if mass is None else np.array([0.0, 0.0, -float(mass) * GRAVITY])

    def emit(self, kind: str, macro: int, text: str) -> None:
        ev = Event(float(self.sim.time), int(self.sim.step_index), kind, macro, text)
        self.events.append(ev)
        if kind in ("macro", "final"):
            self.macro = macro
        if self.on_event is not None:
            self.on_event(ev)

    def step(self, pos: np.ndarray, quat: np.ndarray) -> Any:
        """Command the gripper pose and advance one step; the sensed (noisy, filtered) wrench is
        then in ``self.f`` (N) and ``self.tq`` (N m), world frame (a pose repeated bit for bit costs
        ``set_target`` nothing)."""
        sim = self.sim
        sim.set_target(pos, quat)
        r = sim.step()
        self.f, self.tq = self.cond(r.gripper_force, getattr(r, "gripper_torque", _NO_TORQUE), self.dt)
        if self._noisy:
            self.recent.append((float(r.time), self.f))
        if self.on_step is not None:
            self.on_step(r)
        return r

    def hold(self, pos: np.ndarray, quat: np.ndarray, seconds: float) -> Steps[None]:
        """Command the pose ``pos``, ``quat`` (world, m and wxyz) for ``seconds``."""
        for _ in range(round(seconds / self.dt)):
            self.step(pos, quat)
            yield

    def mocap_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """A copy of the gripper's (mocap body's) pose now: position (m) and quaternion (wxyz), world."""
        mid = self.sim.built.mocap_id
        return self.sim.data.mocap_pos[mid].copy(), self.sim.data.mocap_quat[mid].copy()


def program_steps(
    program: Program, ses: Session, out: Execution, track: DemoTrack | None = None
) -> Steps[None]:
    """The steps of ``program`` (see :func:`dlovr.execution.engine.execute`): its classed macros
    until one fails, then its final motion and the final hold; the outcome lands in ``out``."""
    from dlovr.sim import SimulationDiverged

    sim, opts, classed = ses.sim, ses.opts, program.classed
    ses.emit("start", 0, f"program {program.name}: {len(classed)} macros, detection {opts.detect}")
    try:
        yield from ses.hold(*ses.mocap_pose(), opts.start_settle)
        first = macro_shift(classed[0], opts) if classed else None
        turn = macro_turn(classed[0], opts) if classed else None
        yield from to_start(program.start.start_pos, program.start.start_quat, ses, first, turn)
        if (yield from _classed_steps(classed, ses, out, track)):
            final = program.final
            if final is None and track is not None and classed:
                final = _track_final(classed[-1], track)
            if final is not None:
                yield from run_final(final, ses, track)
                out.final_done = True
            yield from final_hold(ses, out, track)
            ses.emit("end", 0, "program done")
    except SimulationDiverged as e:
        out.diverged = str(e)
        ses.emit("failed", 0, f"simulation diverged outside the macros: {e.reason}")
    out.kept = list(sim.tracker.kept) if sim.tracker is not None else []
    out.sim_time = float(sim.time)


#: Speeds (m/s, rad/s) and the shortest time (s) of the move to a program's start pose.
START_SPEED = 0.02
START_ANGULAR_SPEED = 0.5
START_MIN_S = 0.25


def macro_shift(m: Macro, opts: ExecOptions) -> Vec | None:
    """The shift (m, world) of the objects ``m``'s principal contacts name (those it begins, else
    those it ends; the mean of several), from ``opts.object_shifts``; None where it names none (or
    the run is blind)."""
    if not opts.object_shifts:
        return None
    shifts = dict(opts.object_shifts)
    for contacts in (m.established, m.released):
        names = sorted({o for c in contacts for o in c.objects if o in shifts})
        if names:
            return cast(Vec, tuple(sum(shifts[o][i] for o in names) / len(names) for i in range(3)))
    return None


def macro_turn(m: Macro, opts: ExecOptions) -> Quat | None:
    """The turn (wxyz, world) of the objects ``m``'s principal contacts name, as :func:`macro_shift`
    picks them (an object not in ``opts.object_turns`` is not turned; several: their normalised
    sum); None where it names none or no object is turned."""
    if not opts.object_turns:
        return None
    shifts, turns = dict(opts.object_shifts), dict(opts.object_turns)
    known = shifts.keys() | turns.keys()
    for contacts in (m.established, m.released):
        names = sorted({o for c in contacts for o in c.objects if o in known})
        if names:
            qs = [turns.get(o, IDENTITY) for o in names]
            total = [sum(q[i] for q in qs) for i in range(4)]
            return cast(Quat, tuple(float(x) for x in quat_normalize(total)))
    return None


#: The quaternion of no turn (wxyz).
IDENTITY: Quat = (1.0, 0.0, 0.0, 0.0)


def to_start(
    start_pos: Any, start_quat: Any, ses: Session, shift: Vec | None = None, turn: Quat | None = None
) -> Steps[None]:
    """Move the gripper to the program's start pose (world; turned by ``turn`` and moved by
    ``shift``, the registered motion ``p -> R p + t`` of the first macro's objects) where it starts
    more than 0.1 mm or 1 mrad from it: the robot knows its own pose, and the demonstration started
    there (smoothly, at :data:`START_SPEED`). Nothing where it is there already."""
    start = [float(x) for x in start_pos]
    gq = np.asarray(start_quat, dtype=float)
    gq = gq / math.sqrt(float((gq * gq).sum()))
    if turn is not None:
        start = [float(x) for x in quat_rotate(np.asarray(turn, float), np.asarray(start))]
        gq = quat_normalize(quat_mul(np.asarray(turn, float), gq))
        ses.turn = turn
    goal = [start[i] + (shift[i] if shift is not None else 0.0) for i in range(3)]
    here_p, here_q = ses.sim.target_pos.copy(), ses.sim.target_quat.copy()
    c = min(1.0, abs(dot(here_q.tolist(), gq.tolist())))
    angle = 2.0 * math.acos(c)
    dist = math.dist(goal, here_p.tolist())
    if dist <= 1e-4 and angle <= 1e-3:
        return
    ses.shift = shift if shift is not None else (0.0, 0.0, 0.0)
    period = max(START_MIN_S, dist / START_SPEED, angle / START_ANGULAR_SPEED)
    a = cast(Vec, tuple(float(x) for x in here_p))
    b = cast(Vec, tuple(goal))
    n = max(1, round(period / ses.dt))
    ses.emit("start", 0, f"to the program's start pose: {dist * 1000:.1f} mm, {math.degrees(angle):.1f} deg")
    for k in range(1, n + 1):
        s = k / n
        k_ease = 0.5 * (1.0 - math.cos(math.pi * s))
        q = slerp(here_q, gq, k_ease) if angle > 1e-9 else here_q
        ses.step(np.array(eased(a, b, s)), np.asarray(q))
        yield


def final_hold(ses: Session, out: Execution, track: DemoTrack | None) -> Steps[None]:
    """Hold the last commanded pose ``final_settle`` s; the force sensed over its last
    :data:`GOAL_SENSE_S` (mean) checks the goal against the demonstration's end force
    (:func:`goal_check`), in ``out``. The gripper lags its target at speed (``max_speed``), so where
    the last motion is still under way it catches up first, as the open-loop replay's does (holding
    where the gripper is would drop the end of that motion: a hand's last lift, cut short)."""
    pos, quat = ses.sim.target_pos.copy(), ses.sim.target_quat.copy()
    n_all = round(ses.opts.final_settle / ses.dt)
    n_sense = min(n_all, round(GOAL_SENSE_S / ses.dt))
    total, total_tq = np.zeros(3), np.zeros(3)
    for k in range(n_all):
        ses.step(pos, quat)
        if k >= n_all - n_sense:
            total, total_tq = total + ses.f, total_tq + ses.tq
        yield
    if n_sense > 0:
        sensed = total / n_sense
        judged = _unturned(sensed, ses)
        out.goal_force = cast(Vec, tuple(float(x) for x in sensed))
        out.goal_torque = cast(Vec, tuple(float(x) for x in total_tq / n_sense))
        if track is not None and track.end_force is not None:
            out.goal_force_diff = math.dist(out.goal_force, track.end_force)
        if out.program.goal:  # a goal without contacts has no contact vector to compare
            weight = ses.weight()
            demo_weight = None if _starts_free(out.program) else weight
            tol = out.program.goal_tolerance_deg
            out.goal_sensed, out.goal_angle = goal_check(
                judged, track, ses.opts.noise, n_sense, weight, demo_weight,
                GOAL_ANGLE_DEG if tol is None else tol)
        if out.goal_sensed is not None:
            word = "confirms" if out.goal_sensed else "does not confirm"
            ses.emit("end", 0, f"the sensed contact vector {word} the goal ({out.goal_angle:.1f} deg from "
                     "the demonstration's at its end)")


def _unturned(sensed: np.ndarray, ses: Session) -> np.ndarray:
    """The force sensed (N, world) in the demonstration's frame where the run's objects are turned
    (registered): its environment share (minus the cable's weight) turned back."""
    if ses.turn == IDENTITY:
        return sensed
    w = ses.weight()
    w = np.zeros(3) if w is None else w
    q = np.asarray(ses.turn, float)
    back = quat_rotate(np.array([q[0], -q[1], -q[2], -q[3]]), sensed - w)
    return w + back


def _starts_free(program: Program) -> bool:
    """Whether the demonstration's cable hung free (no principal contacts) while its weight was
    sensed (:data:`FREE_WINDOW_S`): its first transition came after that window."""
    classed = program.classed
    return not classed or (not classed[0].from_contacts and classed[0].t > FREE_WINDOW_S[1])


def _classed_steps(
    macros: tuple[Macro, ...], ses: Session, out: Execution, track: DemoTrack | None
) -> Steps[bool]:
    """The classed macros in order until one does not end well; whether all did."""
    skip = bounces(macros, ses.opts.bounce)
    resume: float | None = None
    for m in macros:
        run = yield from run_macro(m, ses, track, by_motion=m.index in skip, t_from=resume)
        resume = run.resume_at
        out.runs.append(run)
        if run.ended == "diverged":
            out.diverged = run.reason
        if run.ended not in ENDED_OK:
            return False
    return True


def _path(
    m: Macro, sim: Any, opts: ExecOptions, track: DemoTrack | None, t_from: float | None = None,
    tool: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> Any:
    mid = sim.built.mocap_id
    mo = m.motion
    here = (
        cast(Vec, tuple(float(x) for x in sim.data.mocap_pos[mid])),
        cast(Quat, tuple(float(x) for x in sim.data.mocap_quat[mid])),
    )
    frame = m.frame or opts.frame
    if track is not None:
        # the track holds commanded targets, which lead the gripper: go on from the current target
        here = (
            cast(Vec, tuple(float(x) for x in sim.target_pos)),
            cast(Quat, tuple(float(x) for x in sim.target_quat)),
        )
        t0 = m.t - mo.duration if t_from is None else min(t_from, m.t - mo.duration)
        # beyond its stretch the gripper keeps moving as it was when the transition should have come
        # (a turn keeps turning, an approach approaching); the macro's net motion if it held still
        span = max(m.t - t0, opts.min_duration)
        # (a hand's last 0.1 s is its drift and easing: 7 deg/s of turning at the defaults, carried
        # over a 3 s stretch, swings a 25 cm cable's tip centimetres aside: a hand's goes on as its
        # stretch moved on the whole)
        beyond = None if track.by_hand else local_twist(track.t, track.pos, track.quat, t0, m.t, span)
        beyond = beyond or (mo.rotation, mo.relative)
        ease = HAND_EASE_S / span if track.by_hand else 0.0  # the hand's pace into the net motion's
        return TrackPath(
            track.t, track.pos, track.quat, t0, m.t, *here, frame, beyond, tool, ease,
        )
    return ScrewPath(*here, mo.rotation, mo.relative, mo.start_quat, frame, tool)


def macro_period(m: Macro, opts: ExecOptions, track: DemoTrack | None, t_from: float | None = None) -> float:
    if track is None:
        return pace(m, opts)
    t0 = m.t - m.motion.duration if t_from is None else min(t_from, m.t - m.motion.duration)
    return max(m.t - t0, opts.min_duration)


def bounces(macros: Any, within: float) -> set[int]:
    """Indices of macro pairs whose second undoes the first's change of principal contacts within
    ``within`` s of demonstrated motion (a bounce: off and back, or on and off)."""
    out: set[int] = set()
    for a, b in itertools.pairwise(macros):
        sa, sb = ({c.state for c in a.released}, {c.state for c in a.established}), (
            {c.state for c in b.released}, {c.state for c in b.established})
        if b.motion.duration <= within and sa == (sb[1], sb[0]) and (sa[0] or sa[1]):
            out |= {a.index, b.index}
    return out


def arm_at(m: Macro, opts: ExecOptions, track: DemoTrack | None, period: float) -> float:
    """The fraction of the motion after which the force detectors may fire (``opts.arm``; following
    the recorded track, also ``phase_blank`` s into the stretch's last motion phase: the gripper
    setting off or stopping earlier shakes the wrench, which is no transition; at the latest 50 ms
    before the demonstrated transition)."""
    if track is None or period <= 0:
        return opts.arm
    t_start = m.t - period
    phase = last_start(track.t, track.pos, track.quat, t_start, m.t)
    return max(opts.arm, min((phase + opts.phase_blank - t_start) / period, 1.0 - 0.05 / period))


def _allowance_text(m: Macro, opts: ExecOptions, allowed: float) -> str:
    unit = "mm" if m.motion.distance > 1e-9 else "mrad"
    return (
        f"no {m.label} transition detected within the allowance ({opts.allowance:g}x the "
        f"demonstrated motion: {allowed * 1000:.1f} {unit}) and {opts.settle:g} s after it"
    )


def run_macro(
    m: Macro, ses: Session, track: DemoTrack | None, *, by_motion: bool = False, t_from: float | None = None
) -> Steps[MacroRun]:
    """One guarded motion: until the detector fires, or the allowance and then ``settle`` pass;
    ``by_motion`` (or a macro without force signal): until its demonstrated motion is done.

    Where the allowance passes with nothing felt, a script's or a network's macro fails and ends the
    run. A hand's macro (``track.by_hand``) goes on (``"went on"``): the next macro takes up the
    demonstrated motion from where the gripper is, as the demonstration's replay would. A hand's
    transitions come where its drift and its detours happened to bring the cable (an end edge the
    cable slipped off, a tip that grazed a corner); under variation such a transition may come
    unfelt, later, or not at all, and the task need not depend on it.

    Following the recorded track, a macro whose transition came before its demonstrated motion was
    done leaves the rest of that motion to the next one: ``t_from`` (demonstration time, s) is where
    the previous macro's motion stopped, and this one's stretch of the track begins there."""
    from dlovr.sim import SimulationDiverged

    sim, opts = ses.sim, ses.opts
    path, said = hand_path(_path(m, sim, opts, track, t_from, ses.tool), m, opts.give_way, track, ses.tool)
    path, shift = _in_object_frame(path, m, ses)
    period = macro_period(m, opts, track, t_from)
    scale = m.motion.distance if m.motion.distance > 1e-9 else m.motion.angle
    allowed = opts.allowance * scale
    guard = ses.guard = Guard(m, opts, 1.0 / ses.dt, ses.turn)
    arm = arm_at(m, opts, track, period)
    t0 = float(sim.time)
    force = not guard.oracle
    blank = opts.blank if force else 0.0
    started = blank <= 0.0
    if started:
        guard.start(t0, ses.f, ses.tq, ses.recent)
    ses.emit("macro", m.index, f"macro {m.index} {m.label}: {m.expected}{said}")
    limit = opts.allowance * period + opts.settle
    s = 0.0

    def ended(
        how: str, t: float, at: float | None, reason: str = "", resume: float | None = None
    ) -> MacroRun:
        k = min(s, 1.0)  # the part of the object's shift applied
        ses.shift = cast(Vec, tuple(ses.shift[i] + k * shift[i] for i in range(3)))
        return MacroRun(
            macro=m, started_at=t0, ended_at=t, ended=how, detected_at=at, moved=s * scale, allowed=allowed,
            peak_signal=guard.peak, reason=reason, resume_at=resume,
        )

    try:
        while True:
            s = min(opts.allowance, (float(sim.time) + 1e-12 - t0) / period)
            r = ses.step(*path.at(s))
            yield
            t = float(r.time)
            if by_motion or (force and guard.weak):
                if s >= 1.0:
                    why = "a bounce in the demonstration" if by_motion else "no force signal in it"
                    ses.emit("detected", m.index, f"macro {m.index} {m.label}: ended by its motion ({why})")
                    return ended("motion", t, t)
                continue
            if not started:
                if t - t0 >= blank - 1e-12:
                    guard.start(t, ses.f, ses.tq, ses.recent)
                    started = True
                continue
            # after the allowance the gripper stops short, which shakes the cable: in force mode
            # only a transition felt while moving counts (the oracle still waits ``settle``)
            moving = not force or s < opts.allowance
            if guard.update(t, ses.f, ses.tq, r, armed=(not force or s >= arm) and moving):
                at = _detected(m, ses, track, path, r, s, m.t - period + s * period, period)
                return ended("detected", t, t, resume=at)
            if t - t0 >= limit - 1e-12:
                why = _allowance_text(m, opts, allowed)
                if track is not None and track.by_hand:
                    ses.emit("went_on", m.index, f"macro {m.index} {m.label}: {why}; going on with the "
                             "demonstrated motion (a hand's program)")
                    return ended("went on", t, None, why)
                ses.emit("failed", m.index, f"macro {m.index} {m.label}: {why}")
                return ended("allowance", t, None, why)
    except SimulationDiverged as e:
        ses.emit("failed", m.index, f"macro {m.index} {m.label}: simulation diverged: {e.reason}")
        return ended("diverged", float(e.time), None, str(e))


def _in_object_frame(path: Any, m: Macro, ses: Session) -> tuple[Any, Vec]:
    """``path`` moved into the frame of the objects ``m`` names (registered runs): a world-frame
    motion turned with them (:class:`dlovr.execution.motion.TurnedPath`, about where it starts; the
    turn is taken at once, not blended from the previous macro's), and the difference between their
    shift and the shift applied so far added along the motion; and that difference."""
    turn = macro_turn(m, ses.opts)
    if turn is not None:
        ses.turn = turn
    if ses.turn != IDENTITY and (m.frame or ses.opts.frame) == "world":
        pos, quat = path.at(0.0)
        path = TurnedPath(path, ses.turn, cast(Vec, tuple(float(x) for x in pos)),
                          cast(Quat, tuple(float(x) for x in quat)))
    target = macro_shift(m, ses.opts)
    if target is None:
        return path, (0.0, 0.0, 0.0)
    d = cast(Vec, tuple(target[i] - ses.shift[i] for i in range(3)))
    if max(abs(x) for x in d) <= 1e-12:
        return path, d
    return ShiftedPath(path, d), d


def _detected(
    m: Macro, ses: Session, track: DemoTrack | None, path: Any, r: Any, s: float, at_demo: float,
    period: float,
) -> float | None:
    """The macro's transition was seen at ``s`` of its ``path`` (record ``r``): stop there (screw
    paths), learn the tip's offset at its first touch, report; where on the demonstration's clock
    (s) the next macro's motion resumes (None: at its own stretch)."""
    # a detector fires some time after the transition (the step's rise to its threshold, the filters;
    # a noisy sensor's smoothing): the transition came ``lag`` earlier, and the gripper goes back to
    # where it was then (the next macro resumes from there). The lag is how late the same detectors
    # fire on the demonstration's own wrench; without one, the detectors' smoothing alone
    lag = detection_lag(m, ses, track, period, at_demo - s * period)
    s_at = max(s - lag / period, 0.0) if lag > 0.0 else s
    if lag > 0.0:
        pos, quat = path.at(s_at)
        if ses.sense_before_back:
            ses.back = (pos, quat, lag)
        else:
            ses.sim.set_target(pos, quat)
        at_demo -= (s - s_at) * period
    elif track is None:
        ses.sim.set_target(r.gripper_pos, r.gripper_quat)  # stop where the gripper is
    at = at_demo if track is not None and s_at < 1.0 else None
    if not ses.tool_known and touches_tip(m):
        # the approach left undone is the tip's offset, not motion for the next macro
        ses.tool, ses.tool_known, at = tip_offset(path, s_at), True, None
    ses.emit("detected", m.index, f"macro {m.index} {m.label}: transition detected")
    return at


#: The longest detection lag (s) measured on the demonstration that is taken back
#: (:func:`detection_lag`): the detectors compare the force over windows of about 0.15 s
#: (``ref_lag_s``), and a detector that fires later than that on the demonstration does not time its
#: transition.
MAX_DEMO_LAG_S = 0.15


def detection_lag(m: Macro, ses: Session, track: DemoTrack | None, period: float, t0: float) -> float:
    """How long (s) after the transition the macro's force detectors fired, as the executor takes it
    back (:func:`_detected`): as late as they fire on the demonstration's own wrench
    (:func:`demo_detection_lag`, at most :data:`MAX_DEMO_LAG_S`), else their own smoothing
    (:meth:`Guard.lag`); 0 for the oracle. ``period`` (s): the macro's stretch, from ``t0``
    (demonstration time, s)."""
    guard = ses.guard
    if guard is None or guard.oracle:
        return 0.0
    demo = demo_detection_lag(m, ses.opts, track, period, 1.0 / ses.dt, t0)
    return demo if demo is not None and demo <= MAX_DEMO_LAG_S else guard.lag()


def demo_detection_lag(
    m: Macro, opts: ExecOptions, track: DemoTrack | None, period: float, rate_hz: float, t0: float
) -> float | None:
    """:func:`measured_demo_lag`, kept in the track (``DemoTrack.lags``, with the macro: its id names
    it) for the next runs that ask the same (a pure function; the options' ``seed`` draws only the
    run's sensor noise, which it does not use)."""
    if track is None or track.wrench is None:
        return measured_demo_lag(m, opts, track, period, rate_hz, t0)
    known = track.lags
    key = (id(m), replace(opts, seed=0), period, rate_hz, t0)
    got = known.get(key)
    if got is None or got[0] is not m:
        got = known[key] = (m, measured_demo_lag(m, opts, track, period, rate_hz, t0))
    return got[1]


def measured_demo_lag(
    m: Macro, opts: ExecOptions, track: DemoTrack | None, period: float, rate_hz: float, t0: float
) -> float | None:
    """How long (s) after its transition (``m.t``) the macro's own force detectors fire on the
    wrench the demonstration sensed, run as :func:`run_macro` runs them: the recorded force resampled
    at the run's rate (``rate_hz``, linear between samples) and low-passed as the run's sensor chain
    does (``opts.filter_tau``, no noise), the detectors started ``blank`` s into the stretch that
    begins at ``t0`` (demonstration time, s) and lasts ``period`` s, armed from :func:`arm_at` on.
    None without a recorded wrench or where they do not fire within ``period`` after ``m.t``.

    A detection comes this late in a run that repeats the demonstration exactly: the step's rise to
    the threshold and the filters' delay, not motion beyond the demonstrated transition."""
    w = None if track is None else track.wrench
    if w is None or len(w.t) < 2 or period <= 0.0 or rate_hz <= 0.0:
        return None
    guard = Guard(m, opts, rate_hz)
    if not guard.detectors:
        return None
    dt, arm = 1.0 / rate_hz, arm_at(m, opts, track, period)
    start = max(t0 - HISTORY_S, float(w.t[0]))
    ts = np.arange(start, min(m.t + period, float(w.t[-1])) + 0.5 * dt, dt)
    fs = np.stack([np.interp(ts, w.t, w.force[:, i]) for i in range(3)], axis=1)
    cond = WrenchConditioner(NoiseModel(0.0), opts.filter_tau)
    zero, history, started = np.zeros(3), deque(maxlen=max(1, round(HISTORY_S / dt))), False
    for t, raw in zip(ts.tolist(), fs, strict=True):
        f = cond(raw, zero, dt)[0]
        if not started and t >= t0 + opts.blank - 1e-9:
            guard.start(t, f, zero, list(history))
            started = True
        elif started and guard.update(t, f, zero, None, armed=(t - t0) / period >= arm):
            return max(t - m.t, 0.0)
        history.append((t, f))
    return None


def run_final(m: Macro, ses: Session, track: DemoTrack | None) -> Steps[None]:
    """The motion after the last classed transition, to the demonstrated end pose (no detection)."""
    path = _path(m, ses.sim, ses.opts, track, tool=ses.tool)
    period = macro_period(m, ses.opts, track)
    t0 = float(ses.sim.time)
    ses.guard = None
    ses.emit("final", m.index, "final motion to the demonstrated end pose")
    while True:
        s = min(1.0, (float(ses.sim.time) + 1e-12 - t0) / period)
        ses.step(*path.at(s))
        yield
        if s >= 1.0:
            return


def _track_final(last: Macro, track: DemoTrack) -> Macro:
    """The final motion of a program without one: the recorded trajectory after its last macro."""
    t_end = float(track.t[-1])
    mo = replace(last.motion, duration=max(t_end - last.t, 0.0))
    return replace(
        last, index=last.index + 1, kind="final", classes=(), t=t_end, motion=mo, detection=(),
        changes=(), risk="none",
    )
