"""Throughput of robustness trials: trials per minute per core, and the executor's own cost per step.

Run: ``.venv/bin/python benchmarks/bench_trials.py [--program recordings/programs/peg_in_hole.program.json]
[--trials 3] [--baseline]``

Runs ``--trials`` perturbed trials (the issue's variation: cable length +-10 %, stiffness x0.5-2,
friction +-30 %, obstacles +-5 mm) one after the other in this process, with force detection and
the demonstration's recorded path, and prints wall time per trial, simulated seconds per trial,
trials per minute on one core (with ``--baseline`` a trial includes the open-loop replay) and the
share of a step the executor adds on top of the tracking simulator (path, sensing chain, detectors),
measured on the first trial (all its steps) against a bare ``Simulator(track=True).step`` loop over
as many steps.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dlovr.execution.executor import ExecOptions
from dlovr.execution.programs import find_recording, load_program
from dlovr.execution.run import load_track, resolve_scene
from dlovr.execution.trials import TrialSetup, run_trial
from dlovr.execution.variation import parse_vary
from dlovr.geometry import scene_pieces
from dlovr.sim import Simulator

ROOT = Path(__file__).resolve().parents[1]
VARY = ("dlo.length=10%", "dlo.young=0.5..2", "dlo.friction=30%", "objects.pos=0.005")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--program", default=str(ROOT / "recordings/programs/peg_in_hole.program.json"))
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--baseline", action="store_true", help="include the open-loop replay in each trial")
    args = ap.parse_args()

    program = load_program(args.program)
    rec = find_recording(program)
    scene = resolve_scene(program, None, rec)
    track = load_track(rec) if rec is not None else None
    pieces = scene_pieces(scene)
    variations = tuple(parse_vary(v, scene) for v in VARY)
    setup = TrialSetup(program, scene, pieces, track, variations, args.seed, ExecOptions(), args.baseline)

    walls, sims, steps = [], [], []
    for k in range(args.trials):
        t0 = time.perf_counter()
        res = run_trial(setup, k)
        walls.append(time.perf_counter() - t0)
        sims.append(res["program"]["sim_time"] + (res.get("openloop") or {}).get("sim_time", 0.0))
        steps.append(round(sims[-1] / 0.002))
        print(f"trial {k}: {walls[-1]:.2f} s wall, {sims[-1]:.2f} s simulated, "
              f"goal {'reached' if res['program']['success'] else 'missed'}")  # fmt: skip

    # the executor's own cost: the same number of steps of a bare tracking simulator
    sim = Simulator(scene, track=True, pieces=pieces)
    n = max(steps[0], 1)
    t0 = time.perf_counter()
    for _ in range(n):
        sim.step()
    bare = (time.perf_counter() - t0) / n
    per_step = walls[0] / n

    mean_wall = sum(walls) / len(walls)
    simulated = sum(sims) / len(sims)
    print(f"\n{program.name}: {args.trials} trials, {mean_wall:.2f} s wall per trial ({simulated:.2f} s "
          f"simulated), {60.0 / mean_wall:.1f} trials per minute per core")  # fmt: skip
    extra = per_step / bare - 1.0
    print(f"per step: {per_step * 1e6:.0f} us in a trial vs {bare * 1e6:.0f} us for a bare "
          f"Simulator(track=True).step (executor, open loop and setup add {extra:+.0%})")  # fmt: skip


if __name__ == "__main__":
    main()
