"""Judging an execution against the ground truth the contact tracker logged beside it (docs/model.md).

The tracker's debounced situations are not used to steer a force-detected run, only to judge it:

- a macro's **true transition** is the start of the first debounced situation, overlapping the
  macro's time window, that shows the macro's change of principal contacts (those it begins are
  there, those it ends are gone; same states, same faces) when the situation before it did not;
  a detection is **ok** when that situation began no later than ``TRUTH_TOL`` after the detection,
  a **false** detection otherwise; a macro that ended at its allowance **missed** the transition
  when it happened anyway, else saw **no transition**; a macro the executor ended by its motion (no
  force signal in the demonstration, or a bounce) is **ok** when its transition happened, else
  **by motion** (no detection, so never a false one); a hand's macro that nothing was felt for
  within its allowance **went on** with the demonstrated motion (no failure: the goal judges the
  run); **latency** is detection minus true transition (s), for detected macros only;
- the **first deviation** is the first macro whose outcome differed from the plan (any outcome but
  *ok*: a false detection, a transition that did not come, ...): where a failed run went wrong, even
  when every macro "succeeded" as far as the executor could tell;
- the **sensed goal check** (``goal_sensed``; what the robot itself can tell): the contact vector
  sensed over the last 0.2 s of the final hold (the sensed force minus the cable's weight) against
  the one the demonstration sensed at its end, by its angle ``goal_angle``
  (:func:`dlovr.execution.executor.goal_check`);
- the run reaches its **goal** when the last debounced situation has the principal contacts of the
  program's goal situation (the demonstration's last one; extra lower-card contacts do not count,
  being no principal contacts);
- **replans** (with a network to recover through, :mod:`dlovr.execution.recovery`): each time the
  goal check did not confirm the goal, the situation sensed, the network loop's path and the goal
  check after it; the run is **recovered** when it planned again and then reached the goal, and a
  recovered run succeeds even where one of its macros failed.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from dlovr.execution.executor import ENDED_OK, Execution, MacroRun, Replan, principal_states, transition_seen

#: How long after a detection the tracker may take to see the transition it detected (s): force
#: detection may lead the geometric contact label by a fraction of a millimetre of motion.
TRUTH_TOL = 0.05

OUTCOMES = ("ok", "false", "by motion", "went on", "missed", "no transition", "diverged", "not run")


@dataclass(frozen=True)
class MacroScore:
    """One macro of a run, judged. Times in s of simulated time; ``moved``/``allowed`` in m (or rad
    for a pure rotation) along the demonstrated motion."""

    index: int
    classes: str
    expected: str
    started_at: float
    detected_at: float | None
    true_at: float | None
    latency: float | None
    outcome: str
    moved: float
    allowed: float
    reason: str = ""
    #: How the macro's run ended: ``"detected"`` (by its detector), ``"motion"`` (its demonstrated
    #: motion done, no detection asked or possible), ``"went on"`` (a hand's macro not felt within
    #: its allowance: the run went on, :func:`dlovr.execution.executor.run_macro`), or the failure
    #: (``"missed"``, ``"diverged"``...).
    ended: str = ""


@dataclass(frozen=True)
class RunResult:
    """A judged run: ``success`` when no macro failed (each ended as
    :data:`~dlovr.execution.executor.ENDED_OK` allows) and the goal was reached."""

    program: str
    scene: str
    detect: str
    success: bool
    goal_reached: bool
    goal: tuple[str, ...]
    final_situation: str
    final_principals: tuple[str, ...]
    failed_macro: int | None
    reason: str
    macros: tuple[MacroScore, ...]
    sim_time: float
    wall_time: float
    first_deviation: int | None = None
    goal_sensed: bool | None = None
    goal_force_diff: float | None = None
    #: the force (N) and torque (N m) sensed over the last 0.2 s of the final hold (mean, world)
    goal_force: tuple[float, float, float] | None = None
    goal_torque: tuple[float, float, float] | None = None
    #: the angle (deg) between the contact vector sensed at the end and the demonstration's
    goal_angle: float | None = None
    #: the recoveries through a network after the goal check failed (:mod:`dlovr.execution.recovery`)
    replans: tuple[Replan, ...] = ()
    #: whether a replan brought the run to its goal
    recovered: bool = False

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["goal"] = list(self.goal)
        d["final_principals"] = list(self.final_principals)
        return d

    @property
    def false_detections(self) -> int:
        return sum(m.outcome == "false" for m in self.macros)

    @property
    def latencies(self) -> list[float]:
        return [m.latency for m in self.macros if m.outcome == "ok" and m.latency is not None]


def _truth(run: MacroRun, kept: list[Any]) -> float | None:
    end = (run.detected_at if run.detected_at is not None else run.ended_at) + TRUTH_TOL
    seen = [transition_seen(principal_states(k.situation), run.macro) for k in kept]
    for i in range(1, len(kept)):
        k = kept[i]
        if seen[i] and not seen[i - 1] and k.end >= run.started_at and k.start <= end:
            return float(k.start)
    return None


def score_macro(run: MacroRun, kept: list[Any]) -> MacroScore:
    """Judge one macro run against the tracker's debounced situations ``kept``."""
    m = run.macro
    true_at = _truth(run, kept)
    latency = None
    if run.ended == "motion":
        outcome = "ok" if true_at is not None else "by motion"
    elif run.ended == "detected":
        outcome = "ok" if true_at is not None else "false"
        if true_at is not None and run.detected_at is not None:
            latency = run.detected_at - true_at
    elif run.ended == "went on":
        outcome = "went on"
    elif run.ended == "diverged":
        outcome = "diverged"
    else:
        outcome = "missed" if true_at is not None else "no transition"
    return MacroScore(
        m.index, m.label, m.expected, run.started_at, run.detected_at, true_at, latency, outcome,
        run.moved, run.allowed, run.reason, run.ended,
    )


def score(ex: Execution, scene_name: str = "") -> RunResult:
    """Judge an :class:`Execution` (see the module docstring)."""
    macros = [score_macro(r, ex.kept) for r in ex.runs]
    failed = next((r for r in ex.runs if r.ended not in ENDED_OK), None)
    reason = ""
    failed_index = None
    if ex.diverged is not None:
        failed_index = ex.runs[-1].macro.index if ex.runs else 0
        reason = f"simulation diverged: {ex.diverged}"
        if ex.runs and ex.runs[-1].ended in ENDED_OK and ex.final_done:
            failed_index = None  # diverged after the last macro (final motion or settling)
    elif failed is not None:
        failed_index = failed.macro.index
        fm = failed.macro
        reason = f"macro {fm.index} ({fm.label}, {fm.expected}): {failed.reason}"
    ran = {m.index for m in macros}
    for m in ex.program.classed:
        if m.index not in ran:
            macros.append(
                MacroScore(m.index, m.label, m.expected, math.nan, None, None, None, "not run", 0.0, 0.0)
            )
    final = ex.kept[-1].situation if ex.kept else None
    final_p = principal_states(final) if final is not None else ()
    goal = ex.program.goal
    reached = final is not None and final_p == goal
    if not reason and not reached:
        reason = f"final situation {final_p or ('N',)} is not the goal {goal or ('N',)}"
    if reason and ex.diverged is not None and failed_index is None:
        reached = False
    recovered = bool(ex.replans) and reached and ex.diverged is None
    if recovered:
        reason = ""
    success = reached and (failed_index is None or recovered) and ex.diverged is None
    return RunResult(
        program=ex.program.name,
        scene=scene_name,
        detect=ex.options.detect,
        success=success,
        goal_reached=reached,
        goal=goal,
        final_situation=final.format() if final is not None else "",
        final_principals=final_p,
        failed_macro=failed_index,
        reason=reason,
        macros=tuple(macros),
        sim_time=ex.sim_time,
        wall_time=ex.wall_time,
        first_deviation=first_deviation(macros),
        goal_sensed=ex.goal_sensed,
        goal_force_diff=ex.goal_force_diff,
        goal_force=ex.goal_force,
        goal_torque=ex.goal_torque,
        goal_angle=ex.goal_angle,
        replans=tuple(ex.replans),
        recovered=recovered,
    )


def _replan_line(k: int, r: Replan) -> str:
    """One recovery attempt of ``dlovr run``'s report."""
    if not r.node:
        return f"replan {k}: {r.reason}"
    path = " -> ".join(r.path)
    got = "arrived at the goal node" if r.arrived else f"stopped: {r.reason}"
    check = "-" if r.goal_sensed is None else ("confirms" if r.goal_sensed else "does NOT confirm")
    angle = f" ({r.goal_angle:.1f} deg)" if r.goal_angle is not None else ""
    head = f"replan {k}: sensed {r.node} ({r.situation}); network path {path}"
    return f"{head}: {got}; goal check {check}{angle}"


def first_deviation(macros: Any) -> int | None:
    """The index of the first macro (in program order) whose outcome differed from the plan: any
    outcome but ``ok`` of a macro that ran; None when every macro that ran went as planned."""
    ran = sorted((m for m in macros if m.outcome != "not run"), key=lambda m: m.index)
    return next((m.index for m in ran if m.outcome != "ok"), None)


def _t(x: float | None, ms: bool = False) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{x * 1000:+.0f} ms" if ms else f"{x:.3f}"


#: The mark of a macro that ended by motion in ``dlovr run``'s table (explained under the table).
_BY_MOTION = "  (by motion)"


def format_result(res: RunResult) -> str:
    """The per-macro table and the result line, as ``dlovr run`` prints them."""
    head = f"{'#':>3}  {'class':<5} {'detected':>9} {'true':>9} {'latency':>9}  {'outcome':<13} expected"
    lines = [f"program {res.program} in scene {res.scene}, detection {res.detect}", head]
    for m in res.macros:
        mark = _BY_MOTION if m.ended == "motion" else ""
        lines.append(
            f"{m.index:>3}  {m.classes:<5} {_t(m.detected_at):>9} {_t(m.true_at):>9} "
            f"{_t(m.latency, True):>9}  {m.outcome:<13} {m.expected}{mark}"
        )
    if any(m.ended == "motion" for m in res.macros):
        lines.append("(by motion): the macro ended when its demonstrated motion was done, not by a detection")
    if any(m.ended == "went on" for m in res.macros):
        lines.append("went on: nothing was felt within the macro's allowance; a hand's program goes on with "
                     "the demonstrated motion")
    goal = " & ".join(res.goal) or "N"
    if res.goal_sensed is not None and res.goal_angle is not None:
        word = "confirms" if res.goal_sensed else "does NOT confirm"
        lines.append(f"sensed goal check: the contact vector {word} the goal ({res.goal_angle:.1f} deg from "
                     "the demonstration's at its end)")
    lines += [_replan_line(k, r) for k, r in enumerate(res.replans, 1)]
    if res.success:
        how = f" after {len(res.replans)} replan(s) through the network" if res.recovered else ""
        lines.append(f"result: goal reached ({goal}) at t = {res.sim_time:.3f} s{how}")
    else:
        lines.append(f"result: FAILED: {res.reason}")
        lines.append(f"        goal {goal}: {'reached' if res.goal_reached else 'not reached'}")
        if res.first_deviation is not None:
            m = next(x for x in res.macros if x.index == res.first_deviation)
            lines.append(f"        first macro whose outcome differed from the plan: {m.index} ({m.outcome})")
    return "\n".join(lines)
