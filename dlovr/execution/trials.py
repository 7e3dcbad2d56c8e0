"""Robustness trials: a program (and optionally the open-loop replay of its demonstration) on many
perturbed copies of its scene, on local processes or a Ray cluster (:func:`dlovr.batch.run_batch`).

Trial ``k`` of seed ``s`` perturbs the scene with :func:`dlovr.execution.variation.perturb`, runs the
program (:func:`dlovr.execution.run.run_program`) and, with the baseline, replays the demonstration's
gripper commands open loop in the same perturbed scene (:func:`dlovr.execution.run.run_openloop`).
Outputs in the output directory (:func:`write_outputs`): ``trial_KKK.json`` per trial,
``trials.csv`` (one row per trial), ``summary.json`` and ``plot.png`` (success rate of program and
open loop per variation parameter and level).
"""

from __future__ import annotations

import csv
import functools
import io
import itertools
import json
import math
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dlovr.execution.demo_track import DemoTrack
from dlovr.execution.engine import follows_hand
from dlovr.execution.executor import ExecOptions
from dlovr.execution.motion import give_way_m
from dlovr.execution.network_run import NetworkRunResult
from dlovr.execution.recovery import Recovery
from dlovr.execution.run import run_openloop, run_program
from dlovr.execution.scoring import RunResult
from dlovr.execution.variation import Variation, object_shifts, object_turns, perturb
from dlovr.model.planning import NetworkProgram
from dlovr.model.program import Program
from dlovr.outputs import rounded

#: Levels per variation parameter in the summary and the plot.
LEVELS = 3


@dataclass(frozen=True, kw_only=True)
class TrialSetup:
    """Everything a trial needs (picklable, sent to the worker processes).

    ``pieces``: the scene objects' convex decomposition (their own frames, so valid for every
    perturbation); ``track``: the demonstration's gripper trajectory, used by the program when
    ``use_track`` and by the open-loop baseline when ``baseline``; ``record_dir``: when given, each
    trial's program run is also recorded there as ``trial_KKK.mcap`` (:mod:`dlovr.execution.recorded`).
    ``registered``: the program is told where the trial's objects are (their shifts from ``scene``,
    :func:`dlovr.execution.variation.object_shifts`, and their turns,
    :func:`~dlovr.execution.variation.object_turns`); else it runs blind. ``force``: an existing
    ``trial_KKK.mcap`` is replaced (else the trial fails: its recording is kept).
    ``program``: a compiled program or a :class:`dlovr.model.planning.NetworkProgram`.
    ``recovery``: a compiled program that misses its goal plans again through this network
    (:mod:`dlovr.execution.recovery`).
    """

    program: Program | NetworkProgram
    scene: Any
    pieces: Any
    track: DemoTrack | None
    variations: tuple[Variation, ...]
    seed: int
    opts: ExecOptions
    baseline: bool = False
    use_track: bool = True
    record_dir: str | None = None
    registered: bool = False
    force: bool = False
    recovery: Recovery | None = None

    @property
    def name(self) -> str:
        """The program's name (a network program's may be empty: ``network``)."""
        return self.program.name if isinstance(self.program, Program) else self.program.name or "network"

    @property
    def give_way(self) -> float:
        """The give-way (m) the program's runs apply (:func:`dlovr.execution.motion.give_way_m`): the
        option, else by whether the track they follow is a hand's (a program compiled smoothed)."""
        return give_way_m(self.opts.give_way, self.use_track and follows_hand(self.program, self.track))

    @property
    def goal(self) -> tuple[str, ...]:
        """The compiled program's goal principal contacts (none for a network program)."""
        return self.program.goal if isinstance(self.program, Program) else ()


def run_trial(setup: TrialSetup, trial: int) -> dict[str, Any]:
    """One trial (see the module docstring) as a JSON-able dict."""
    t0 = time.perf_counter()
    scene, values = perturb(setup.scene, setup.variations, setup.seed, trial)
    from dataclasses import replace

    opts = replace(setup.opts, seed=setup.seed * 100003 + trial)  # noise differs between trials
    if setup.registered:
        opts = replace(opts, object_shifts=object_shifts(setup.scene, scene),
                       object_turns=object_turns(setup.scene, scene))
    track = setup.track if setup.use_track else None
    # the compiled program and the track its open-loop replay follows, when the trial runs one
    replayed = (setup.program, setup.track) if (
        setup.baseline and setup.track is not None and isinstance(setup.program, Program)) else None
    # the program's run and the open-loop replay track contacts in the same scene: its geometry once
    geometry = None
    if replayed is not None and setup.record_dir is None:
        from dlovr.geometry import SceneGeometry

        geometry = SceneGeometry.from_scene(scene, pieces=setup.pieces)  # as Simulator(track=True) makes it
    if setup.record_dir is not None:
        from dlovr.execution.recorded import record_run

        Path(setup.record_dir).mkdir(parents=True, exist_ok=True)
        path = Path(setup.record_dir) / f"trial_{trial:03d}.mcap"
        meta = _trial_metadata(setup, trial, values)
        res = record_run(
            setup.program, scene, path, opts, track=track, pieces=setup.pieces, extra_metadata=meta,
            overwrite=setup.force, recovery=setup.recovery,
        )
    else:
        res = run_program(
            setup.program, scene, opts, track=track, pieces=setup.pieces, recovery=setup.recovery,
            geometry=geometry,
        )
    out: dict[str, Any] = {"trial": trial, "seed": setup.seed, "values": values, **_trial_result(res)}
    if replayed is not None:
        program, demo = replayed
        out["openloop"] = run_openloop(program, scene, demo, pieces=setup.pieces, geometry=geometry).to_json()
    out["wall_time"] = time.perf_counter() - t0
    return out


def _trial_result(res: RunResult | NetworkRunResult) -> dict[str, Any]:
    """A trial's run under ``program``; a network program's result JSON under ``network_run``, and
    under ``program`` the fields the summary reads (no per-macro latencies: network macros are not
    judged one by one)."""
    if isinstance(res, RunResult):
        return {"program": res.to_json()}
    prog = {"success": res.success, "goal_reached": res.goal_reached, "failed_macro": None,
            "reason": res.reason, "macros": [], "path": list(res.path), "replans": res.replans}
    return {"program": prog, "network_run": res.to_json()}


@functools.lru_cache(maxsize=8)
def _scene_digest(path: str) -> str:
    """The hash of the scene file at ``path`` and its meshes (read once per process, not per trial)."""
    from dlovr.recording.bundle import SceneBundle

    return SceneBundle.from_path(path).digest


def _trial_metadata(setup: TrialSetup, trial: int, values: dict[str, Any]) -> dict[str, str]:
    """A recorded trial's metadata: trial, seed, drawn values and the unperturbed scene's hash
    (``base_scene_sha256``), so that recorded trials of one scene merge into a network."""
    return {"trial": str(trial), "seed": str(setup.seed), "vary": json.dumps(values),
            "base_scene_sha256": _scene_digest(str(setup.scene.path))}


def run_trials(
    setup: TrialSetup,
    n: int,
    *,
    workers: int = 1,
    cluster: str | None = None,
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Trials ``0..n-1`` through :func:`dlovr.batch.run_batch`: in this process (``workers`` 1), on
    ``workers`` local processes, or on Ray (``cluster`` ``local`` or an address); results in trial
    order, the same wherever they ran (each trial's draws depend on the seed and its number only).

    A trial whose task failed (it raised, or its worker died on every attempt) is a failed result
    with the reason, never an exception; ``attempts`` says how many runs each trial took (> 1: its
    worker died and it ran again). ``progress`` draws a progress bar on stderr.
    """
    from dlovr.batch import Task, run_batch

    tasks = [Task(f"trial {k}", (setup, k)) for k in range(n)]
    results: dict[int, dict[str, Any]] = {}
    batch = run_batch(
        run_trial, tasks, workers=workers, cluster=cluster, progress=progress, label=f"{n} trials"
    )
    for r in batch:
        out = r.value if r.ok else lost_trial(setup, r.index, str(r.error))
        results[r.index] = {**out, "attempts": r.attempts}
    return [results[k] for k in range(n)]


def lost_trial(setup: TrialSetup, trial: int, error: str) -> dict[str, Any]:
    """The failed result of a trial whose task gave no result (``error``: why)."""
    _, values = perturb(setup.scene, setup.variations, setup.seed, trial)
    reason = f"trial lost: {error}"
    program = {
        "program": setup.name, "scene": setup.scene.name, "detect": setup.opts.detect,
        "success": False, "goal_reached": False, "goal": list(setup.goal), "final_situation": "",
        "final_principals": [], "failed_macro": None, "reason": reason, "macros": [], "sim_time": 0.0,
        "wall_time": 0.0,
    }
    out: dict[str, Any] = {"trial": trial, "seed": setup.seed, "values": values, "program": program}
    if setup.baseline and setup.track is not None:
        out["openloop"] = {"goal_reached": False, "final_situation": "", "final_principals": [],
                           "reason": reason, "sim_time": 0.0, "wall_time": 0.0}
    out["wall_time"] = 0.0
    return out


# --------------------------------------------------------------------------------------------------
# Summary, CSV and plot


def _bins(v: Variation) -> list[tuple[float, float]]:
    if v.kind == "offset":
        lo, hi = 0.0, v.hi * math.sqrt(3.0)
        edges = [lo + (hi - lo) * i / LEVELS for i in range(LEVELS + 1)]
    elif v.kind == "range":
        a, b = math.log(v.lo), math.log(v.hi)
        edges = [math.exp(a + (b - a) * i / LEVELS) for i in range(LEVELS + 1)]
    else:
        edges = [v.lo + (v.hi - v.lo) * i / LEVELS for i in range(LEVELS + 1)]
    return list(itertools.pairwise(edges))


def _rate(xs: Sequence[bool]) -> float | None:
    return sum(xs) / len(xs) if xs else None


def goal_check_counts(trials: Sequence[dict[str, Any]]) -> dict[str, int]:
    """How the sensed goal check (``goal_sensed``, :func:`dlovr.execution.executor.goal_check`)
    judged the program's runs against the tracker: of the ``missed`` runs that did not reach the
    goal it ``caught`` those it did not confirm; of the ``reached`` ones it ``doubted`` those it did
    not confirm. Runs without a check (no demonstrated end force) are left out."""
    checked = [t["program"] for t in trials if t["program"].get("goal_sensed") is not None]
    missed = [p for p in checked if not p["goal_reached"]]
    reached = [p for p in checked if p["goal_reached"]]
    return {"missed": len(missed), "caught": sum(not p["goal_sensed"] for p in missed),
            "reached": len(reached), "doubted": sum(not p["goal_sensed"] for p in reached)}


def replan_counts(trials: Sequence[dict[str, Any]]) -> dict[str, int]:
    """How the recovery through a network went (:mod:`dlovr.execution.recovery`): the trials that
    planned again (``replanned``), those it brought to the goal (``recovered``) and the attempts in
    all (``attempts``). A network program's trials count their own replans (a number, not recovery
    attempts) and are left out."""
    progs = [t["program"] for t in trials]
    done = [p for p in progs if isinstance(p.get("replans"), (list, tuple)) and p["replans"]]
    return {"replanned": len(done), "recovered": sum(bool(p.get("recovered")) for p in done),
            "attempts": sum(len(p["replans"]) for p in done)}


def summarize(trials: Sequence[dict[str, Any]], setup: TrialSetup) -> dict[str, Any]:
    """Success rates, detection figures and per-level rates of a set of trials."""
    prog = [bool(t["program"]["success"]) for t in trials]
    has_ol = all("openloop" in t for t in trials) and bool(trials)
    ol = [bool(t["openloop"]["goal_reached"]) for t in trials] if has_ol else []
    macros = [m for t in trials for m in t["program"]["macros"] if m["outcome"] != "not run"]
    lat = [m["latency"] for m in macros if m["outcome"] == "ok" and m["latency"] is not None]
    false = sum(m["outcome"] == "false" for m in macros)
    failures: dict[str, int] = {}
    deviations: dict[str, int] = {}
    for t in trials:
        p = t["program"]
        if not p["success"]:
            key = f"macro {p['failed_macro']}" if p["failed_macro"] else p["reason"].split(":")[0]
            failures[key] = failures.get(key, 0) + 1
            dev = p.get("first_deviation")
            dkey = f"macro {dev}" if dev is not None else "none"
            deviations[dkey] = deviations.get(dkey, 0) + 1
    per: dict[str, list[dict[str, Any]]] = {}
    for v in setup.variations:
        rows = []
        for lo, hi in _bins(v):
            inside = [
                i for i, t in enumerate(trials)
                if lo <= v.level(t["values"][v.key]) <= hi + 1e-12 and not (hi < v.level(t["values"][v.key]))
            ]
            rows.append(
                {
                    "level": [lo, hi],
                    "trials": len(inside),
                    "program": _rate([prog[i] for i in inside]),
                    "openloop": _rate([ol[i] for i in inside]) if has_ol else None,
                }
            )
        per[v.key] = rows
    walls = [t["wall_time"] for t in trials]
    return {
        "program": setup.name,
        "scene": setup.scene.name,
        "trials": len(trials),
        "seed": setup.seed,
        "vary": [f"{v.key}={v.spec}" for v in setup.variations],
        "detect": setup.opts.detect,
        "noise_n": setup.opts.noise,
        "sensor_noise_n": setup.opts.assumed_noise,
        "registered": setup.registered,
        "give_way_m": setup.give_way,
        "path": "demo" if setup.use_track and setup.track is not None else "program",
        "program_success_rate": _rate(prog),
        "openloop_success_rate": _rate(ol) if has_ol else None,
        "program_only": sum(p and not o for p, o in zip(prog, ol, strict=True)) if has_ol else None,
        "openloop_only": sum(o and not p for p, o in zip(prog, ol, strict=True)) if has_ol else None,
        "macros_run": len(macros),
        "false_detections": false,
        "false_detection_rate": false / len(macros) if macros else None,
        "missed_detections": sum(m["outcome"] == "missed" for m in macros),
        "went_on": sum(m["outcome"] == "went on" for m in macros),
        "median_latency_s": statistics.median(lat) if lat else None,
        "latencies": len(lat),
        "failures": failures,
        "first_deviations": deviations,
        "goal_check": goal_check_counts(trials),
        "replans": replan_counts(trials),
        "per_parameter": per,
        "wall_time_per_trial_s": statistics.mean(walls) if walls else None,
        "retried_trials": sum(t.get("attempts", 1) > 1 for t in trials),
        "lost_trials": sum(t["program"]["reason"].startswith("trial lost:") for t in trials),
    }


def result_names(n: int, record: bool = False) -> list[str]:
    """The files ``n`` trials write into their output folder (:func:`write_outputs`; with ``record``
    also their recordings ``trial_KKK.mcap``): what ``run --trials`` refuses to replace without
    ``--force``."""
    names = [f"trial_{k:03d}.json" for k in range(n)] + ["trials.csv", "summary.json", "plot.png"]
    return names + ([f"trial_{k:03d}.mcap" for k in range(n)] if record else [])


def write_outputs(
    out_dir: str | Path, trials: Sequence[dict[str, Any]], summary: dict[str, Any], *, force: bool = False
) -> list[Path]:
    """Write the per-trial JSON, ``trials.csv``, ``summary.json`` and ``plot.png``; their paths.

    Each file is written atomically (:func:`dlovr.outputs.write_output`: a temporary file renamed into
    place); an existing one is replaced only with ``force`` (else :class:`dlovr.outputs.OutputError`,
    and a file another writer made meanwhile is kept)."""
    from dlovr.outputs import atomic_output, prepare_output_dir, write_output

    out = prepare_output_dir(out_dir)
    paths = []
    for t in trials:
        p = out / f"trial_{t['trial']:03d}.json"
        write_output(p, json.dumps(rounded(t), indent=1) + "\n", force=force)
        paths.append(p)
    write_output(out / "trials.csv", _csv_text(trials), force=force)
    paths.append(out / "trials.csv")
    write_output(out / "summary.json", json.dumps(rounded(summary), indent=1) + "\n", force=force)
    paths.append(out / "summary.json")
    with atomic_output(out / "plot.png", force=force) as tmp:
        plot(summary, tmp)
    paths.append(out / "plot.png")
    return paths


def _csv_text(trials: Sequence[dict[str, Any]]) -> str:
    """``trials.csv``: one row per trial (its values, outcome, detections, latency, wall time)."""
    keys = sorted({k for t in trials for k in t["values"]})
    buf = io.StringIO(newline="")
    w = csv.writer(buf)
    w.writerow(["trial", *keys, "program_success", "failed_macro", "reason", "openloop_goal",
                "false_detections", "median_latency_s", "wall_time_s"])
    for t in trials:
        p = t["program"]
        lat = [m["latency"] for m in p["macros"] if m["outcome"] == "ok" and m["latency"] is not None]
        vals = [_cell(rounded(t["values"].get(k))) for k in keys]
        w.writerow([t["trial"], *vals, p["success"], p["failed_macro"] or "", p["reason"],
                    t["openloop"]["goal_reached"] if "openloop" in t else "",
                    sum(m["outcome"] == "false" for m in p["macros"]),
                    rounded(statistics.median(lat)) if lat else "", round(t["wall_time"], 3)])
    return buf.getvalue()


def _cell(x: Any) -> Any:
    return json.dumps(x) if isinstance(x, list) else x


def _level_label(key: str, level: Sequence[float] | None) -> str:
    if level is None:
        return ""
    if key.endswith(".pos"):
        return f"{level[0] * 1000:.1f}-{level[1] * 1000:.1f} mm"
    if key.endswith(".yaw"):
        return f"{level[0]:.1f}-{level[1]:.1f} deg"
    return f"x{level[0]:.2f}-{level[1]:.2f}"


def plot(summary: dict[str, Any], path: str | Path) -> Path:
    """Bar charts of the success rate of program and open loop per variation parameter and level."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    per = summary["per_parameter"]
    keys = list(per) or ["all"]
    fig, axes = plt.subplots(1, len(keys) + 1, figsize=(3.2 * (len(keys) + 1), 3.2), squeeze=False)
    total = {
        "level": None,
        "trials": summary["trials"],
        "program": summary["program_success_rate"],
        "openloop": summary["openloop_success_rate"],
    }
    groups = [("all trials", [total])]
    groups += [(k, per[k]) for k in per]
    for ax, (key, rows) in zip(axes[0], groups, strict=False):
        xs = list(range(len(rows)))
        prog = [r["program"] if r["program"] is not None else 0.0 for r in rows]
        ax.bar([x - 0.2 for x in xs], prog, width=0.4, label="program", color="tab:blue")
        if summary.get("openloop_success_rate") is not None:
            ol = [r["openloop"] if r["openloop"] is not None else 0.0 for r in rows]
            ax.bar([x + 0.2 for x in xs], ol, width=0.4, label="open loop", color="tab:orange")
        labels = [_level_label(key, r["level"]) + f"\n(n={r['trials']})" for r in rows]
        ax.set_xticks(xs, labels, fontsize=7)
        ax.set_ylim(0, 1.05)
        ax.set_title(key, fontsize=9)
    axes[0][0].set_ylabel("goal reached (fraction of trials)")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"{summary['program']}: {summary['trials']} trials, seed {summary['seed']}, "
                 f"detection {summary['detect']}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100, format="png")  # format: the path may be a temporary name
    plt.close(fig)
    return Path(path)
