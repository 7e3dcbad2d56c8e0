"""Cost of contact-state extraction on top of bare MuJoCo stepping, at 40 and 80 segments.

Run: ``.venv/bin/python benchmarks/bench_sim.py [--scene peg_in_hole] [--script FILE] [--repeat N]``

Plays the scene's built-in demonstration (``scenes/NAME.script.toml``) along one command stream, side
by side in one run, three ways (interleaved, best of ``--repeat``):

- bare: ``mj_step`` only (the gripper's mocap pose is set untimed);
- sim: ``Simulator.step`` without tracking: gripper motion, divergence checks, the per-step record
  with the raw contact arrays and gripper force;
- sim+extract: ``Simulator(track=True).step``: the above plus contact-state extraction (topology,
  discrete states, forces, debouncing) every step.

Prints µs per step, the ratio of sim+extract to bare (the issue's target: at most 1.15 at 40
segments), the real-time factor of sim+extract (2 ms step / wall time per step) and how often the
tracker labelled all queried points or some of them (the rest of the steps reuse their labels).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import mujoco

from dlovr.scene import load_scene, scenes_dir
from dlovr.script import load_script
from dlovr.sim import DEFAULT_MAX_STRETCH, SimulationDiverged, Simulator


def _commands(scene, script, max_stretch):
    sim = Simulator(scene, max_stretch=max_stretch)
    return [(rec.target_pos, rec.target_quat) for rec in sim.run(script)]


def bare(scene, targets, max_stretch) -> float:
    sim = Simulator(scene, max_stretch=max_stretch)
    m, d = sim.model, sim.data
    total = 0.0
    for pos, quat in targets:
        sim.target_pos, sim.target_quat = pos, quat
        sim._move_mocap()
        t0 = time.perf_counter()
        mujoco.mj_step(m, d)
        total += time.perf_counter() - t0
    return total / len(targets)


def stepped(scene, targets, max_stretch, track: bool) -> tuple[float, Simulator]:
    sim = Simulator(scene, max_stretch=max_stretch, track=track)
    t0 = time.perf_counter()
    for pos, quat in targets:
        sim.target_pos, sim.target_quat = pos, quat
        sim.step()
    return (time.perf_counter() - t0) / len(targets), sim


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="peg_in_hole")
    ap.add_argument("--script", type=Path, default=None, help="default: scenes/SCENE.script.toml")
    ap.add_argument(
        "--max-stretch", type=float, default=DEFAULT_MAX_STRETCH, help="divergence bound on segment stretch"
    )
    ap.add_argument("--segments", type=int, nargs="+", default=[40, 80])
    ap.add_argument("--repeat", type=int, default=2, help="interleaved rounds; the best of each is kept")
    args = ap.parse_args()
    script_path = args.script or scenes_dir() / f"{args.scene}.script.toml"
    if not script_path.is_file():
        raise SystemExit(f"no script {script_path}; give --script")
    script = load_script(script_path)
    print(f"mujoco {mujoco.__version__}; {args.scene}; {script_path.name}; best of {args.repeat}")
    head = ("segments", "steps", "bare µs", "sim µs", "sim+extract µs", "ratio", "RTF", "labelled all/some")
    print("{:>8} {:>6} {:>8} {:>8} {:>15} {:>6} {:>6} {:>18}".format(*head))
    for segments in args.segments:
        scene = load_scene(args.scene)
        scene = replace(scene, dlo=replace(scene.dlo, segments=segments))
        try:
            targets = _commands(scene, script, args.max_stretch)
            b = s = f = float("inf")
            for _ in range(args.repeat):
                b = min(b, bare(scene, targets, args.max_stretch))
                s = min(s, stepped(scene, targets, args.max_stretch, False)[0])
                t, sim = stepped(scene, targets, args.max_stretch, True)
                f = min(f, t)
        except SimulationDiverged as e:
            print(f"{segments:>8} diverged: {e}")
            continue
        n, tr = len(targets), sim.tracker
        lab = f"{tr.labellings / n:.1%} / {tr.partial_labellings / n:.1%}"
        row = (segments, n, b * 1e6, s * 1e6, f * 1e6, f / b, 0.002 / f, lab)
        print("{:>8} {:>6} {:>8.1f} {:>8.1f} {:>15.1f} {:>6.2f} {:>6.2f} {:>18}".format(*row))


if __name__ == "__main__":
    main()
