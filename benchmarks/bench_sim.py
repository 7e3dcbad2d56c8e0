"""Bare ``mj_step`` time per step at 40 and 80 segments, side by side.

Run: ``.venv/bin/python benchmarks/bench_sim.py [--seconds 2] [--scene peg_in_hole]``.

Without ``--scene`` (or while ``dlovr.scene`` is not available) the benchmark uses a built-in table
drag: a 0.6 m cable lying on a table, dragged sideways at 5 cm/s, so that most segments are in contact.
Columns: segments, steps, bare mj_step µs/step, real-time factor (2 ms step / wall time per step).
(Step + contact-state extraction columns are to be added with the contact pipeline.)
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import mujoco
import numpy as np

from dlovr.sim import DloParams, GripperPose, Obstacle, Simulator

Q_X = (math.cos(math.pi / 4), 0.0, -math.sin(math.pi / 4), 0.0)  # G_z = -x: cable along +x


def _table_sim(segments: int) -> Simulator:
    hx, hy, hz = 0.5, 0.5, 0.02
    box = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    table = Obstacle("table", [box], pos=(0.0, 0.0, 0.7))
    dlo = DloParams(length=0.6, radius=0.005, segments=segments)
    return Simulator.from_parts([table], dlo, GripperPose((-0.3, 0.0, 0.7255), Q_X))


def _scene_sim(name: str, segments: int) -> Simulator:
    from dlovr.scene import load_scene

    scene = load_scene(name)
    scene = replace(scene, dlo=replace(scene.dlo, segments=segments))
    return Simulator(scene)


def bench(sim: Simulator, seconds: float) -> tuple[int, float]:
    m, d = sim.model, sim.data
    mid = sim.built.mocap_id
    dt = m.opt.timestep
    nsteps = round(seconds / dt)
    sim.step(100)  # settle
    v = np.array([0.0, 0.05, 0.0]) * dt
    t = 0.0
    for _ in range(nsteps):
        d.mocap_pos[mid] += v  # steady drag; moving the mocap is not timed
        t0 = time.perf_counter()
        mujoco.mj_step(m, d)
        t += time.perf_counter() - t0
    if not np.all(np.isfinite(d.qpos)):
        raise SystemExit("benchmark diverged")
    return nsteps, t / nsteps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=2.0, help="simulated seconds per case")
    ap.add_argument("--scene", default=None, help="scene name (default: built-in table drag)")
    args = ap.parse_args()
    print(f"mujoco {mujoco.__version__}, scene: {args.scene or 'built-in table drag'}")
    print(f"{'segments':>8} {'steps':>7} {'mj_step µs/step':>16} {'real-time factor':>17}")
    for segments in (40, 80):
        sim = _scene_sim(args.scene, segments) if args.scene else _table_sim(segments)
        n, per = bench(sim, args.seconds)
        print(f"{segments:>8} {n:>7} {per * 1e6:>16.1f} {sim.model.opt.timestep / per:>17.2f}")


if __name__ == "__main__":
    main()
