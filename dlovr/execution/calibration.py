"""Calibrating a program's detectors in simulation before it is written (docs/programs.md, "Calibrated
detection"; docs/people.md).

A demonstration can leave a transition without a force signal: a person's hand stopped its drag the
moment the cable's tip reached the groove's corner, so the step the corner makes cannot be told from
the hand stopping, or the new situation held 28 ms, too briefly to measure a step. The derivation
(:mod:`dlovr.model.derivation`) then marks the detection "no signal" or "weak signal", and the
program repeats the demonstrated motion there and no more: a cable a few per cent longer trails
further behind the gripper and is not yet where the demonstration's was when the motion stops.

Calibration runs the compiled program in the demonstration's own scene with a few cables changed
(:data:`VARIANTS`: their length and stiffness, what decides how far the cable trails and how it
bends), each macro that has no force signal ended by the simulator's contact tracker (ground truth,
the executor's ``oracle``: the expected change of principal contacts seen), and records the wrench
the gripper's sensor reads. Where the tracker saw the transition, the same derivation as from a
demonstration (:func:`dlovr.model.derivation.derive`: baseline, step, threshold above the quiet
level, cone) is applied to the run's wrench at that moment. The runs' results are combined (the
smallest step, the largest noise and quiet level, the widest cone) and the combined detector is
replayed on every run's wrench: it must fire after the transition and no later than
:data:`MAX_LATE_S`, never before. Only then does the macro get the calibrated parameters (each text
``calibrated: ...``) and end by detection, with the allowance as before; otherwise it keeps the
demonstration's (ending by its motion) and the program says why in ``calibration``.

Nothing of the benchmark's trials is used: the variants are fixed factors of the demonstration's
scene, without random draws.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from dlovr.execution.demo_track import DemoTrack
from dlovr.execution.engine import smoothed
from dlovr.execution.executor import (
    ENDED_OK,
    HISTORY_S,
    ExecOptions,
    Guard,
    Session,
    arm_at,
    bounces,
    macro_period,
    principal_states,
    run_macro,
    to_start,
    transition_seen,
)
from dlovr.model.derivation import DerivationRules, WrenchSeries, derive
from dlovr.model.detection import THRESHOLD_PARAM
from dlovr.model.margins import blind
from dlovr.model.program import Detection, Macro, Program

#: The cables calibration runs with (scene key, factor): the demonstration's cable 5 % shorter and
#: longer (a longer cable trails further behind a dragging gripper and touches sooner), and 0.7x
#: and 1.4x as stiff (a stiffer cable springs back, a softer one sags). Half of the standard
#: variation's bounds (length +-10 %, Young 0.5..2): far enough to move a transition by millimetres,
#: near enough that the transition still comes, so that the signal is measured where it exists.
VARIANTS: tuple[tuple[str, float], ...] = (
    ("length", 0.95), ("length", 1.05), ("young", 0.7), ("young", 1.4),
)
#: After the transition the tracker saw, how much later (s) the calibrated detector may fire in a
#: calibration run (the detectors compare over 0.15 s windows; a detection this late is still the
#: transition's).
MAX_LATE_S = 0.15
#: How long (s) before the tracker's transition the detector may fire (the force may change a few
#: steps before the contact label does).
MAX_EARLY_S = 0.01
#: How long (s) a run goes on after the last macro it calibrates (the step is measured over the
#: 0.15 s after the transition).
AFTER_S = 0.3


@dataclass(frozen=True)
class Seen:
    """One calibration run's sight of one macro's transition: when the macro started (``t0`` s, run
    time), its stretch of the demonstration (``period`` s) and where it resumed (``t_from``), when the
    tracker saw the transition (``t``) and until when it held (``t_next``)."""

    t0: float
    period: float
    t_from: float | None
    t: float
    t_next: float


@dataclass
class RunLog:
    """What one calibration run recorded: the wrench per step as the sensor chain gives it to the
    detectors (times s, force N, torque N m, world; the low-pass of :class:`ExecOptions`, no
    noise), what the tracker saw of the calibrated macro's transition (``seen``; None: not seen)
    and why the run stopped short (``stopped``; empty: it did not)."""

    label: str
    t: list[float]
    force: list[np.ndarray]
    torque: list[np.ndarray]
    seen: Seen | None = None
    stopped: str = ""
    #: the calibrated macro's start, stretch and resumption (its ``t``, ``t_next`` NaN), once it ran
    macro: Seen | None = None

    def wrench(self) -> WrenchSeries:
        return WrenchSeries(np.asarray(self.t), np.asarray(self.force), np.asarray(self.torque))


def _drain(gen: Generator[None, None, Any]) -> Any:
    """Run a step generator to its end; its outcome."""
    try:
        while True:
            next(gen)
    except StopIteration as stop:
        return stop.value


def _watch(m: Macro, log: RunLog, state: dict[str, Any], ses: list[Session]) -> Callable[[Any], None]:
    """The ``on_step`` of a calibration run: record the wrench as the session's sensor chain gives it
    to the detectors (``ses[0]``: through its low-pass); while ``state["on"]`` (``m`` runs,
    and after it), since when the tracker shows ``m``'s transition (``state["since"]``) and, once it
    was taken (``state["taken"]``), when it stopped showing it (``state["until"]``)."""

    def on_step(r: Any) -> None:
        t = float(r.time)
        log.t.append(t)
        log.force.append(np.array(ses[0].f, dtype=float))
        log.torque.append(np.array(ses[0].tq, dtype=float))
        st = getattr(r, "state", None)
        if not state["on"] or st is None or state["until"] is not None:
            return
        if transition_seen(principal_states(st.discrete), m):
            if state["since"] is None:
                state["since"] = t
        elif state["taken"]:
            state["until"] = t
        else:
            state["since"] = None

    return on_step


def calibration_run(
    program: Program, scene: Any, label: str, target: int, path: DemoTrack | None,
    pieces: Any = None, opts: ExecOptions | None = None,
) -> RunLog:
    """Run ``program`` in ``scene`` as a run runs it up to its macro ``target`` (an index), that one
    ended by the tracker (the oracle: ground truth), then hold :data:`AFTER_S`; the wrench and what
    the tracker saw (:class:`RunLog`). ``path``: the track the program follows, its demonstration's
    smoothed as compiled (:func:`dlovr.execution.engine.smoothed`; made once for all the runs)."""
    from dlovr.execution.run import fresh_simulator
    from dlovr.sim import SimulationDiverged

    opts = opts if opts is not None else ExecOptions()
    log = RunLog(label, [], [], [])
    sim, why = fresh_simulator(scene, pieces)
    if sim is None:
        log.stopped = str(why)
        return log
    m_target = next(m for m in program.classed if m.index == target)
    state: dict[str, Any] = {"on": False, "since": None, "taken": False, "until": None}
    held: list[Session] = []
    ses = Session(sim, opts, on_step=_watch(m_target, log, state, held))
    held.append(ses)
    skip = bounces(program.classed, opts.bounce)
    try:
        _drain(to_start(program.start.start_pos, program.start.start_quat, ses))
        resume: float | None = None
        for m in program.classed:
            oracle = m.index == target
            ses.opts = replace(opts, detect="oracle") if oracle else opts
            state["on"] = oracle
            t0, t_from = float(sim.time), resume
            period = macro_period(m, opts, path, resume)
            run = _drain(run_macro(m, ses, path, by_motion=m.index in skip, t_from=resume))
            resume = run.resume_at
            if oracle:
                log.macro = Seen(t0, period, t_from, math.nan, math.nan)
                if run.ended == "detected" and state["since"] is not None:
                    state["taken"] = True
                    log.seen = Seen(t0, period, t_from, float(state["since"]), math.inf)
                else:
                    log.stopped = f"macro {m.index} {m.label}: not seen by the tracker ({run.ended})"
                break
            if run.ended not in ENDED_OK:
                log.stopped = f"macro {m.index} {m.label}: {run.ended}"
                break
        ses.opts = opts
        if log.seen is not None:
            _drain(ses.hold(*ses.mocap_pose(), AFTER_S))
    except SimulationDiverged as e:
        log.stopped = f"diverged: {e.reason}"
    if log.seen is not None:
        until = state["until"]
        log.seen = replace(log.seen, t_next=float(until) if until is not None else log.t[-1])
    return log


def variant_scene(scene: Any, key: str, factor: float) -> Any:
    """``scene`` with its cable's ``key`` (a :data:`VARIANTS` key) multiplied by ``factor``."""
    return replace(scene, dlo=replace(scene.dlo, **{key: getattr(scene.dlo, key) * factor}))


def _vectors(m: Macro) -> tuple[list[Any], list[Any], list[Any]]:
    """The contact vectors ``m``'s transition releases and establishes, and its pinch axes."""
    axes = [c.axis for c in (*m.released, *m.established) if c.axis is not None]
    return [c.vector for c in m.released], [c.vector for c in m.established], axes


def combined(
    cls: str, m: Macro, logs: Sequence[RunLog], opts: ExecOptions, track: DemoTrack | None,
    rules: DerivationRules | None = None,
) -> tuple[dict[str, float], str] | tuple[None, str]:
    """The parameters of ``m``'s ``cls`` detector from the calibration runs ``logs`` (each of which
    saw the transition), or None and why there is no usable signal: per run the derivation from the
    run's wrench (:func:`dlovr.model.derivation.derive`, its quiet level from where the run's
    detector is armed, :func:`dlovr.execution.executor.arm_at` of ``opts`` following ``track``)
    with and without its fraction of the step;
    then the smallest step, the largest noise, the threshold at least every run's floor (noise,
    quiet level) and the fraction of the smallest step, the widest cone. Usable where that threshold
    is below the smallest step and the step at least :data:`dlovr.model.detection.MIN_SNR` times the
    noise."""
    from dlovr.model.detection import MIN_SNR

    r = rules or DerivationRules()
    released, established, axes = _vectors(m)
    derived, floors = [], []
    for log in logs:
        s = log.seen
        assert s is not None
        w = log.wrench()
        armed = s.t0 + arm_at(m, opts, track, s.period) * s.period
        derived.append(derive(cls, released, established, w, s.t0, s.t, s.t_next, r, axes, armed).params)
        floors.append(derive(cls, released, established, w, s.t0, s.t, s.t_next,
                             replace(r, fraction=0.0), axes, armed).params)
    key = THRESHOLD_PARAM[cls]
    steps = [float(p.get("step_n", 0.0)) for p in derived]
    step, noise = min(steps), max(float(p.get("noise_n", 0.0)) for p in derived)
    thr = max(max(float(p[key]) for p in floors), r.fraction * step)
    if thr >= step or step < MIN_SNR * noise:
        return None, (f"steps {min(steps):.3g}-{max(steps):.3g} N, threshold {thr:.3g} N, "
                      f"noise {noise:.3g} N: no usable signal")
    params = dict(derived[0])
    params.update({key: round(thr, 6), "step_n": round(step, 6), "noise_n": round(noise, 6)})
    if "max_angle_deg" in params:
        params["max_angle_deg"] = max(float(p["max_angle_deg"]) for p in derived)
    dirs = [np.array([p["dir_x"], p["dir_y"], p["dir_z"]]) for p in derived if "dir_x" in p]
    if dirs:
        u = sum(dirs, np.zeros(3))
        u = u / max(float(np.linalg.norm(u)), 1e-12)
        params.update({f"dir_{a}": round(float(x), 6) for a, x in zip("xyz", u, strict=True)})
    return params, f"steps {min(steps):.3g}-{max(steps):.3g} N, threshold {thr:.3g} N, noise {noise:.3g} N"


def fires_at(m: Macro, log: RunLog, opts: ExecOptions, track: DemoTrack | None) -> float | None:
    """When (s, run time) ``m``'s detectors fire on the wrench of a calibration run (as the sensor
    chain gave it) as a run would run them: started ``opts.blank`` into the macro and armed from
    :func:`dlovr.execution.executor.arm_at` on; None if they never fire."""
    s = log.seen
    assert s is not None
    rate = 1.0 / float(np.median(np.diff(log.t)))
    guard = Guard(m, opts, rate)
    arm = arm_at(m, opts, track, s.period)
    zero, history = np.zeros(3), deque(maxlen=max(1, round(HISTORY_S * rate)))
    started = False
    for t, f in zip(log.t, log.force, strict=True):
        if t < s.t0:
            history.append((t, f))
            continue
        if not started and t >= s.t0 + opts.blank - 1e-9:
            guard.start(t, f, zero, list(history))
            started = True
        elif started and guard.update(t, f, zero, None, armed=(t - s.t0) / s.period >= arm):
            return t
    return None


def _texts(d: Detection, params: dict[str, float], how: str) -> dict[str, str]:
    """Per parameter of a calibrated detection, how it was obtained."""
    key = THRESHOLD_PARAM[d.cls]
    out = {}
    for k in params:
        if k == key:
            out[k] = (f"calibrated: {how}; at least every run's 4x noise and 1.25x quiet level and 40% "
                      "of the smallest step")
        elif k == "step_n":
            out[k] = f"calibrated: the smallest step along the watched direction over the runs ({how})"
        elif k == "noise_n":
            out[k] = f"calibrated: the largest noise before the transition over the runs ({how})"
        elif k == "max_angle_deg":
            out[k] = f"calibrated: the widest cone the runs' steps needed ({how})"
        elif k.startswith("dir_"):
            out[k] = f"calibrated: the runs' mean step direction ({how})"
        else:
            out[k] = d.derivation.get(k, f"calibrated: {how}")
    return out


def calibrated_macro(
    m: Macro, logs: Sequence[RunLog], opts: ExecOptions, track: DemoTrack | None, runs: str,
) -> tuple[Macro | None, str]:
    """``m`` with detections calibrated from the runs ``logs`` (:func:`combined`), checked by replaying
    them on every run's wrench (:func:`fires_at`: after the transition the tracker saw, less
    :data:`MAX_EARLY_S`, and within :data:`MAX_LATE_S`); or None and why not. ``runs`` describes the
    runs for the texts."""
    unseen = [log for log in logs if log.seen is None]
    if unseen:
        return None, (f"the tracker saw the transition in {len(logs) - len(unseen)} of {len(logs)} runs "
                      f"({unseen[0].label}: {unseen[0].stopped or 'not seen'}): kept")
    dets, whys = [], []
    for d in m.detection:
        params, why = combined(d.cls, m, logs, opts, track)
        if params is None:
            return None, f"{d.cls}: {why}: kept"
        how = f"{len(logs)} runs in the demonstration's scene ({runs}), {why}"
        dets.append(replace(d, params=params, derivation=_texts(d, params, how)))
        whys.append(f"{d.cls}: {why}")
    new = replace(m, detection=tuple(dets))
    for log in logs:
        s = log.seen
        assert s is not None
        at = fires_at(new, log, opts, track)
        if at is None or at < s.t - MAX_EARLY_S or at > s.t + MAX_LATE_S:
            when = "never" if at is None else f"{(at - s.t) * 1000:+.0f} ms from the transition"
            return None, f"{'; '.join(whys)}, but the detector fires {when} in the run {log.label}: kept"
    return new, "; ".join(whys) + ": calibrated"


def calibrate(
    program: Program, scene: Any, track: DemoTrack | None, pieces: Any = None,
    opts: ExecOptions | None = None, variants: Sequence[tuple[str, float]] = VARIANTS,
) -> Program:
    """``program`` with the detectors of its macros without force signal (:func:`dlovr.model.margins.blind`)
    calibrated in simulation (the module's docstring): per such macro, in order, one run in
    ``scene`` (the demonstration's) and one per cable of ``variants``, the prefix run with the
    macros calibrated so far. ``calibration`` says what was run and, per macro, what came of it."""
    opts = opts if opts is not None else ExecOptions()
    path = smoothed(program, track)
    runs = [("as demonstrated", scene)] + [
        (f"cable {key} x{f:g}", variant_scene(scene, key, f)) for key, f in variants
    ]
    desc = "the cable as demonstrated, " + ", ".join(label.removeprefix("cable ") for label, _ in runs[1:])
    targets = [m.index for m in program.classed if blind(m, opts.min_snr)]
    notes = []
    for k in targets:
        m = next(x for x in program.macros if x.index == k)
        logs = [calibration_run(program, sc, label, k, path, pieces, opts) for label, sc in runs]
        new, note = calibrated_macro(m, logs, opts, path, desc)
        notes.append(f"macro {k} {m.label}: {note}")
        if new is not None:
            program = replace(program, macros=tuple(new if x.index == k else x for x in program.macros))
    head = (f"{len(runs)} runs per macro without force signal in the demonstration's scene "
            f"({desc}), each ended by the contact tracker")
    text = head + (": " + "; ".join(notes) if notes else ": none to calibrate")
    return replace(program, calibration=text)


def calibrate_recording(program: Program, recording: str | Path) -> Program:
    """:func:`calibrate` ``program`` in the scene its demonstration ``recording`` names (a built-in
    scene, loaded as ``dlovr run`` loads it: :func:`dlovr.execution.run.resolve_scene`), following
    the recording's track; without such a scene the program says so and is not calibrated."""
    from dlovr.execution.demo_track import load_track
    from dlovr.execution.run import resolve_scene
    from dlovr.geometry import scene_pieces
    from dlovr.inputs import InputError

    try:
        scene = resolve_scene(program, None, Path(recording))
    except InputError as e:
        return replace(program, calibration=f"not calibrated: {e}")
    return calibrate(program, scene, load_track(recording), scene_pieces(scene))
