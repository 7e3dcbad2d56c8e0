"""Batch throughput on Ray and local processes, measured side by side in one run.

Run: ``.venv/bin/python benchmarks/bench_batch.py [--trials 8] [--sim-time 3.0] [--short 100]``

1. Trial-like tasks of about 1 s of CPU each (the table scene simulated for ``--sim-time`` seconds
   with contact tracking, the gripper lowered with a seeded sideways offset so that the cable lands on
   the table): trials per minute with 1 and 2 Ray workers on one local Ray instance of 2 CPUs (target:
   2 workers at least 1.8x 1 worker), and with 1 and 2 local worker processes for reference. The values
   must be the same everywhere (same seeds, same results).
2. ``--short`` short tasks (the same trial, 0.02 s of simulated time: mostly building the simulator):
   wall time on Ray and on local processes, 2 workers each: Ray's overhead per task. Local processes
   are forked anew for each batch (that is in their time); Ray's workers stay up between batches.

Ray starts once (its start-up time is printed apart) and every engine runs a warm-up batch first, so
that worker start-up (imports) is not timed. Rounds alternate between the engines; the best of each
counts (the machine is shared and noisy).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import time

import numpy as np

from dlovr.batch import Task, run_batch
from dlovr.scene import load_scene
from dlovr.sim import Simulator


def trial(seed: int, sim_time: float) -> tuple[int, str]:
    """One trial: lower the gripper 0.4 m with a seeded offset of up to 15 cm in x and y, simulate
    ``sim_time`` s; return the number of contact-state changes and a digest of the final cable."""
    sim = Simulator(load_scene("table"), track=True)
    rng = np.random.default_rng(seed)
    offset = [rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), -0.4]
    sim.set_target(sim.target_pos + np.array(offset))
    sim.step(round(sim_time / sim.model.opt.timestep))
    return len(sim.tracker.changes), hashlib.sha256(sim.points().tobytes()).hexdigest()[:16]


def timed(tasks: list[Task], **kw) -> tuple[float, dict[str, tuple[int, str]]]:
    t0 = time.perf_counter()
    results = list(run_batch(trial, tasks, progress=False, **kw))
    wall = time.perf_counter() - t0
    bad = [r for r in results if not r.ok or r.retried]
    assert not bad, bad
    return wall, {r.key: r.value for r in results}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=8, help="trial-like tasks per measurement")
    ap.add_argument("--sim-time", type=float, default=3.0, help="simulated seconds per trial")
    ap.add_argument("--short", type=int, default=100, help="short tasks in the overhead measurement")
    ap.add_argument("--rounds", type=int, default=2, help="alternating rounds; the best of each counts")
    args = ap.parse_args()

    import ray

    from dlovr.batch.on_ray import connect

    load = "/".join(f"{x:.1f}" for x in os.getloadavg())
    print(f"machine: {os.cpu_count()} cores, load average {load} (1/5/15 min); Ray {ray.__version__}")
    t0 = time.perf_counter()
    connect(ray, "local", 2)
    print(f"Ray start-up (local instance, 2 CPUs): {time.perf_counter() - t0:.1f} s")
    try:
        trials = [Task(f"trial{s}", (s, args.sim_time)) for s in range(args.trials)]
        short = [Task(f"short{s}", (s, 0.02)) for s in range(args.short)]
        engines = {
            "Ray, 1 worker": {"cluster": "local", "workers": 1},
            "Ray, 2 workers": {"cluster": "local", "workers": 2},
            "local, 1 worker": {"workers": 1},
            "local, 2 workers": {"workers": 2},
        }
        for kw in engines.values():  # warm-up: every worker has imported dlovr and built a scene
            timed(trials[:2], **kw)
        t1, c1 = time.perf_counter(), time.process_time()
        trial(0, args.sim_time)
        one, cpu = time.perf_counter() - t1, time.process_time() - c1
        print(f"one trial in this process: {one:.2f} s wall, {cpu:.2f} s CPU ({args.sim_time} s simulated)")

        best: dict[str, float] = {}
        values: dict[str, dict] = {}
        for _ in range(args.rounds):
            for name, kw in engines.items():
                wall, vals = timed(trials, **kw)
                best[name] = min(best.get(name, wall), wall)
                values[name] = vals
        same = all(v == values["local, 1 worker"] for v in values.values())
        print(f"\n{args.trials} trials, best of {args.rounds} rounds; same values on every engine: {same}")
        for name, wall in best.items():
            print(f"  {name:<17} {wall:6.2f} s  {60 * args.trials / wall:6.1f} trials/min")
        r_ray = best["Ray, 1 worker"] / best["Ray, 2 workers"]
        r_loc = best["local, 1 worker"] / best["local, 2 workers"]
        print(f"  speed-up with 2 workers: Ray {r_ray:.2f}x (target >= 1.8x), local processes {r_loc:.2f}x")

        timed(short[:4], cluster="local", workers=2)
        over: dict[str, float] = {}
        for _ in range(args.rounds):
            for name, kw in (("Ray", {"cluster": "local", "workers": 2}), ("local", {"workers": 2})):
                wall, _ = timed(short, **kw)
                over[name] = min(over.get(name, wall), wall)
        per = (over["Ray"] - over["local"]) / args.short * 1000
        print(f"\n{args.short} short tasks, 2 workers, best of {args.rounds} rounds")
        print(f"  Ray   {over['Ray']:6.2f} s  ({over['Ray'] / args.short * 1000:.1f} ms per task)")
        print(
            f"  local {over['local']:6.2f} s  ({over['local'] / args.short * 1000:.1f} ms per task; "
            "includes forking its 2 worker processes, Ray's workers are already running)"
        )
        print(f"  Ray / local {over['Ray'] / over['local']:.2f}x: Ray's overhead {per:+.1f} ms per task")
        load = "/".join(f"{x:.1f}" for x in os.getloadavg())
        print(f"\nload average at the end: {load}")
    finally:
        ray.shutdown()


if __name__ == "__main__":
    main()
