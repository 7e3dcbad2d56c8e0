"""Cost of contact-state extraction on top of bare MuJoCo stepping, at 40 and 80 segments.

Run: ``.venv/bin/python benchmarks/bench_sim.py [--scene peg_in_hole] [--script FILE]``

Plays the scene's built-in demonstration (``scenes/NAME.script.toml``) twice per segment count, side
by side in one run: once timing bare ``mj_step`` only (the gripper's mocap is moved untimed), once
timing the full pipeline (``Simulator.step`` with its checks and contact arrays, plus
``ContactTracker.update``: topology, discrete states, debouncing). Prints µs per step, their ratio
and the real-time factor of the full pipeline (2 ms step / wall time per step).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import mujoco

from dlovr.contacts import ContactTracker
from dlovr.geometry import SceneGeometry
from dlovr.scene import load_scene, scenes_dir
from dlovr.script import load_script
from dlovr.sim import SimulationDiverged, Simulator


def bench(scene_name: str, script_path: Path, segments: int, max_stretch: float) -> tuple[int, float, float]:
    scene = load_scene(scene_name)
    scene = replace(scene, dlo=replace(scene.dlo, segments=segments))
    script = load_script(script_path)

    sim = Simulator(scene, max_stretch=max_stretch)  # bare mj_step along the same command stream
    bare = 0.0
    targets = []
    for rec in sim.run(script):
        targets.append((rec.target_pos, rec.target_quat))
    sim = Simulator(scene, max_stretch=max_stretch)
    m, d = sim.model, sim.data
    for pos, quat in targets:
        sim.target_pos, sim.target_quat = pos, quat
        sim._move_mocap()
        t0 = time.perf_counter()
        mujoco.mj_step(m, d)
        bare += time.perf_counter() - t0

    sim = Simulator(scene, max_stretch=max_stretch)  # full pipeline
    tracker = ContactTracker(SceneGeometry.from_scene(scene), scene.params)
    full = 0.0
    for pos, quat in targets:
        t0 = time.perf_counter()
        sim.target_pos, sim.target_quat = pos, quat
        tracker.update(sim.step())
        full += time.perf_counter() - t0
    n = len(targets)
    return n, bare / n, full / n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="peg_in_hole")
    ap.add_argument("--script", type=Path, default=None, help="default: scenes/SCENE.script.toml")
    ap.add_argument(
        "--max-stretch",
        type=float,
        default=0.5,
        help="divergence bound on segment stretch (the scenes' cables are tuned for their own segment "
        "count; at other counts the demo may stretch beyond the usual 10%%: timing is still valid)",
    )
    ap.add_argument("--segments", type=int, nargs="+", default=[40, 80])
    args = ap.parse_args()
    script = args.script or scenes_dir() / f"{args.scene}.script.toml"
    if not script.is_file():
        raise SystemExit(f"no script {script}; give --script")
    print(f"mujoco {mujoco.__version__}; scene {args.scene}; script {script.name}")
    head = ("segments", "steps", "bare mj_step µs", "step+extract µs", "ratio", "RTF")
    print("{:>8} {:>7} {:>16} {:>16} {:>6} {:>6}".format(*head))
    for segments in args.segments:
        try:
            n, bare, full = bench(args.scene, script, segments, args.max_stretch)
        except SimulationDiverged as e:
            print(f"{segments:>8} diverged: {e}")
            continue
        row = (segments, n, bare * 1e6, full * 1e6, full / bare, 0.002 / full)
        print("{:>8} {:>7} {:>16.1f} {:>16.1f} {:>6.2f} {:>6.2f}".format(*row))


if __name__ == "__main__":
    main()
