"""Throughput of robustness trials: trials per minute per core, and the executor's own cost per step.

Run: ``.venv/bin/python benchmarks/bench_trials.py [--program recordings/programs/peg_in_hole.program.json]
[--trials 3] [--baseline] [--gc default|freeze] [--own-rounds 3]``

Runs ``--trials`` perturbed trials (the variation of docs/programs.md: cable length +-10 %, stiffness x0.5-2,
friction +-30 %, obstacles +-5 mm) one after the other in this process, with force detection and
the demonstration's recorded path, and prints wall time per trial, simulated seconds per trial,
trials per minute on one core (with ``--baseline`` a trial includes the open-loop replay) and the
time per step the executor adds on top of the tracking simulator (path, sensing chain, detectors),
from one more run of trial 0's program with ``Simulator.step`` timed apart. The trials' thread CPU
time (median) gives trials per minute per core without the other processes' share of a shared
machine; ``--gc freeze`` freezes the setup's objects first (``gc.freeze``, as ``dlovr run`` does).
``--own-rounds N`` (default 3; 0: not) also measures the executor's own thread CPU per step alone:
trial 0's program run again with its records handed back by a stand-in ``Simulator.step`` (no
MuJoCo, no tracker), the figure that other processes on a shared machine move least.
"""

from __future__ import annotations

import argparse
import gc
import statistics
import time
from pathlib import Path
from typing import Any

from dlovr.execution.demo_track import load_track
from dlovr.execution.engine import execute
from dlovr.execution.executor import ExecOptions
from dlovr.execution.run import find_recording, resolve_scene
from dlovr.execution.trials import TrialSetup, run_trial
from dlovr.execution.variation import parse_vary, perturb
from dlovr.geometry import scene_pieces
from dlovr.model.program import Program
from dlovr.sim import Simulator

ROOT = Path(__file__).resolve().parents[1]
VARY = ("dlo.length=10%", "dlo.young=0.5..2", "dlo.friction=30%", "objects.pos=0.005")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "bench_trials").splitlines()[0])
    ap.add_argument("--program", default=str(ROOT / "recordings/programs/peg_in_hole.program.json"))
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--baseline", action="store_true", help="include the open-loop replay in each trial")
    ap.add_argument("--own-rounds", type=int, default=3,
                    help="rounds of the executor's own cost measured alone (0: not)")
    ap.add_argument("--gc", choices=("default", "freeze"), default="default",
                    help="freeze: gc.freeze() after the setup, as `dlovr run --trials` does")
    args = ap.parse_args()

    program = Program.load(args.program)
    rec = find_recording(program)
    scene = resolve_scene(program, None, rec)
    track = load_track(rec) if rec is not None else None
    pieces = scene_pieces(scene)
    variations = tuple(parse_vary(v, scene) for v in VARY)
    setup = TrialSetup(program=program, scene=scene, pieces=pieces, track=track, variations=variations,
                       seed=args.seed, opts=ExecOptions(), baseline=args.baseline)

    if args.gc == "freeze":
        gc.freeze()
    walls, cpus, sims = [], [], []
    for k in range(args.trials):
        t0, c0 = time.perf_counter(), time.thread_time()
        res = run_trial(setup, k)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.thread_time() - c0)
        sims.append(res["program"]["sim_time"] + (res.get("openloop") or {}).get("sim_time", 0.0))
        print(f"trial {k}: {walls[-1]:.2f} s wall, {cpus[-1]:.2f} s thread CPU, {sims[-1]:.2f} s simulated, "
              f"goal {'reached' if res['program']['success'] else 'missed'}")

    # the executor's own cost per step: a run of the program with the simulator's step timed apart
    scene0, _ = perturb(scene, variations, args.seed, 0)
    sim = Simulator(scene0, track=True, pieces=pieces)
    real_step, spent = sim.step, [0.0, 0]

    def timed_step(n: int = 1):
        t = time.perf_counter()
        r = real_step(n)
        spent[0] += time.perf_counter() - t
        spent[1] += n
        return r

    sim.step = timed_step
    t0 = time.perf_counter()
    execute(program, sim, ExecOptions(), track=track)
    total = time.perf_counter() - t0
    step_us = spent[0] / spent[1] * 1e6
    own_us = (total - spent[0]) / spent[1] * 1e6

    own = executor_own(program, scene0, pieces, track, args.own_rounds) if args.own_rounds else []

    mean_wall = sum(walls) / len(walls)
    simulated = sum(sims) / len(sims)
    print(f"\n{program.name}: {args.trials} trials, {mean_wall:.2f} s wall per trial ({simulated:.2f} s "
          f"simulated), {60.0 / mean_wall:.1f} trials per minute per core")
    med_cpu = statistics.median(cpus)
    print(f"thread CPU per trial: median {med_cpu:.2f} s (trials {', '.join(f'{c:.2f}' for c in cpus)}): "
          f"{60.0 / med_cpu:.1f} trials per minute per core of CPU time (gc: {args.gc})")
    print(f"per step of a program run: {step_us:.0f} us in Simulator(track=True).step, {own_us:.0f} us in "
          f"the executor (path, sensing chain, detectors): {own_us / step_us:.1%} on top")
    if own:
        print(f"the executor's own thread CPU per step, alone (that run's records handed back by a stand-in "
              f"Simulator.step, {len(own)} rounds): min {min(own):.1f} us, "
              f"median {statistics.median(own):.1f} us")


def executor_own(program: Program, scene: Any, pieces: Any, track: Any, rounds: int) -> list[float]:
    """The executor's own thread CPU per step (us), without the simulation: a real run of ``program``
    keeps its records, then each round runs it again with ``Simulator.step`` handing those records
    back in order (the simulator's clock set from them), so that the same macros, paths, sensing
    chain and detectors run and nothing of MuJoCo or the tracker does. One value per round."""
    records: list[Any] = []
    execute(program, Simulator(scene, track=True, pieces=pieces), ExecOptions(), track=track,
            on_step=records.append)
    out = []
    for _ in range(rounds):
        sim = Simulator(scene, track=True, pieces=pieces)
        replayed = iter(records)

        def handed_back(n: int = 1, sim: Any = sim, replayed: Any = replayed) -> Any:
            rec = next(replayed)
            sim.data.time, sim.step_index = rec.time, rec.step
            return rec

        sim.step = handed_back
        c0 = time.thread_time()
        execute(program, sim, ExecOptions(), track=track)
        out.append((time.thread_time() - c0) / len(records) * 1e6)
    return out


if __name__ == "__main__":
    main()
