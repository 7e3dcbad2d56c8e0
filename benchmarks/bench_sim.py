"""Cost of contact-state extraction on top of bare MuJoCo stepping, at 40 and 80 segments.

Run: ``.venv/bin/python benchmarks/bench_sim.py [--scene peg_in_hole] [--script FILE] [--repeat N]
[--clock cpu|wall]``

Plays the scene's built-in demonstration (``scenes/NAME.script.toml``) along one command stream, side
by side in one run, three ways (interleaved, best of ``--repeat``):

- bare: ``mj_step`` only (the gripper's mocap pose is set untimed);
- sim: ``Simulator.step`` without tracking: gripper motion, divergence checks, the per-step record
  with the raw contact arrays and gripper force;
- sim+extract: ``Simulator(track=True).step``: the above plus contact-state extraction (topology,
  discrete states, forces, debouncing) every step.

Prints µs per step, the ratio of sim+extract to bare (targets: at most 1.3 at 40 segments, 1.2 at
80), the real-time factor of sim+extract (2 ms step / time per step) and how often the tracker
labelled all queried points or some of them (the rest of the steps keep their labels).

``--clock cpu`` (the default) times with this thread's CPU time, ``wall`` with the wall clock: on a
shared machine the CPU time leaves out the time other processes hold the cores, which the wall clock
charges to whichever variant ran then.
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


CLOCK = time.thread_time


def bare(scene, targets, max_stretch) -> float:
    sim = Simulator(scene, max_stretch=max_stretch)
    m, d = sim.model, sim.data
    clock = CLOCK
    total = 0.0
    for pos, quat in targets:
        sim.target_pos, sim.target_quat = pos, quat
        sim._move_mocap()
        t0 = clock()
        mujoco.mj_step(m, d)
        total += clock() - t0
    return total / len(targets) - _clock_cost()


def _clock_cost() -> float:
    """About one clock read (s): what an interval between two reads carries besides the work, taken
    off bare's per-step times (an iteration below makes two reads)."""
    n = 20000
    t0 = CLOCK()
    for _ in range(n):
        a = CLOCK()
        CLOCK() - a
    return (CLOCK() - t0) / n / 2.0


def stepped(scene, targets, max_stretch, track: bool) -> tuple[float, Simulator]:
    sim = Simulator(scene, max_stretch=max_stretch, track=track)
    t0 = CLOCK()
    for pos, quat in targets:
        sim.target_pos, sim.target_quat = pos, quat
        sim.step()
    return (CLOCK() - t0) / len(targets), sim


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="peg_in_hole")
    ap.add_argument("--script", type=Path, default=None, help="default: scenes/SCENE.script.toml")
    ap.add_argument(
        "--max-stretch", type=float, default=DEFAULT_MAX_STRETCH, help="divergence bound on segment stretch"
    )
    ap.add_argument("--segments", type=int, nargs="+", default=[40, 80])
    ap.add_argument("--repeat", type=int, default=2, help="interleaved rounds; the best of each is kept")
    ap.add_argument("--clock", choices=("cpu", "wall"), default="cpu", help="thread CPU time or wall clock")
    args = ap.parse_args()
    global CLOCK
    CLOCK = time.thread_time if args.clock == "cpu" else time.perf_counter
    script_path = args.script or scenes_dir() / f"{args.scene}.script.toml"
    if not script_path.is_file():
        raise SystemExit(f"no script {script_path}; give --script")
    script = load_script(script_path)
    print(f"mujoco {mujoco.__version__}; {args.scene}; {script_path.name}; best of {args.repeat}; "
          f"{args.clock} time")
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
