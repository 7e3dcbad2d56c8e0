"""Recording overhead, replay speed and compile throughput, measured side by side in one run.

Run: ``.venv/bin/python benchmarks/bench_recording.py [--scene peg_in_hole] [--segments 40] [--copies 8]
[--replays 5] [--no-compile] [--gc default|freeze|both]``

1. simulation (step + contact extraction) alone vs the same with recording to MCAP (target: at most
   10% more);
2. ``replay --verify`` of that recording as a real-time factor, beside bare ``mj_step`` along the same
   commands (its real-time factor bounds the replay's), and their throughput ratio in wall-clock time
   (the replay's steps per second against bare ``mj_step``'s, medians of ``--replays`` interleaved
   rounds; target: at least 0.85; the replay's contact tracker works on a second core), and in CPU
   time of all threads (what the replay costs, the tracker's thread included);
3. ``dlovr compile`` throughput in recordings per second with 1 and 2 workers (``--no-compile``: not).

``--gc freeze`` freezes the objects made before each round of 2. (``gc.freeze``, as ``dlovr replay``
does after its setup); ``--gc both`` replays once more frozen in each round and prints that ratio too.

``--segments N`` records the scene with an N-segment cable (a copy of the scene file with that count,
embedded in the recording as usual).
"""

from __future__ import annotations

import argparse
import gc
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from dlovr.geometry import SceneGeometry
from dlovr.recording import DemoRecorder, replay
from dlovr.scene import load_scene, scenes_dir
from dlovr.script import load_script
from dlovr.sim import Simulator
from dlovr.sim.tracker import ContactTracker


def simulate(scene_name: str, script_path: Path, out: Path | None) -> float:
    scene = load_scene(scene_name)
    script = load_script(script_path)
    sim = Simulator(scene)
    tracker = ContactTracker(SceneGeometry.from_scene(scene), scene.params)
    t0 = time.perf_counter()
    if out is None:
        for rec in sim.run(script):
            tracker.update(rec)
    else:
        with DemoRecorder(out, scene, sim, tracker) as dr:
            for rec in sim.run(script):
                tracker.update(rec)
                dr.step(rec)
    return time.perf_counter() - t0


def scene_with_segments(scene_name: str, segments: int, tmp: Path) -> str:
    """A copy of the built-in scene's directory whose scene file has an ``segments``-segment cable."""
    src = scenes_dir()
    dst = tmp / "scenes"
    shutil.copytree(src, dst)
    path = dst / f"{scene_name}.toml"
    text, n = re.subn(r"(?m)^segments\s*=\s*\d+", f"segments = {segments}", path.read_text())
    if n != 1:
        raise SystemExit(f"{path.name}: no single 'segments = N' line to change")
    path.write_text(text)
    return str(path)


def bare_rtf(scene_name: str, script_path: Path, clock=time.perf_counter) -> float:
    """Real-time factor of bare ``mj_step`` along the script's commands (the gripper's pose set untimed)."""
    import mujoco

    scene = load_scene(scene_name)
    sim = Simulator(scene)
    targets = [(r.target_pos, r.target_quat) for r in Simulator(scene).run(load_script(script_path))]
    total = 0.0
    for pos, quat in targets:
        sim.target_pos, sim.target_quat = pos, quat
        sim._move_mocap()
        t0 = clock()
        mujoco.mj_step(sim.model, sim.data)
        total += clock() - t0
    return len(targets) * sim.model.opt.timestep / total


def _nothing(sim, record) -> None:
    """An ``on_step`` that reads nothing (a replay with one tracks inline)."""


def replay_cpu(path: Path):
    """``replay --verify`` of ``path``: its result and the CPU seconds per step of its loop, all
    threads (its contact tracker works on a thread of its own: ``dlovr.sim.behind.tracking_behind``),
    from the end of its first step (read at its first progress call) to the end of the replay."""
    marks: list[tuple[int, float]] = []
    res = replay(path, verify=True, progress=lambda done, total: marks.append((done, time.process_time())))
    end = time.process_time()
    d0, c0 = marks[0]
    return res, (end - c0) / max(res.steps - d0, 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "bench_recording").splitlines()[0])
    ap.add_argument("--scene", default="peg_in_hole")
    ap.add_argument("--script", type=Path, default=None, help="default: scenes/SCENE.script.toml")
    ap.add_argument("--copies", type=int, default=8, help="recordings compiled in the throughput test")
    ap.add_argument("--repeat", type=int, default=3, help="interleaved runs with and without recording")
    ap.add_argument("--segments", type=int, default=None, help="the cable's segments (default: the scene's)")
    ap.add_argument("--replays", type=int, default=3, help="interleaved rounds of replay and bare mj_step")
    ap.add_argument("--no-compile", action="store_true", help="leave out the compile throughput")
    ap.add_argument("--gc", choices=("default", "freeze", "both"), default="default",
                    help="freeze: gc.freeze() before each round (as `dlovr replay` does after its setup); "
                         "both: each round's replay also once frozen, its ratio printed beside")
    args = ap.parse_args()
    script = args.script or scenes_dir() / f"{args.scene}.script.toml"
    sim_time = load_script(script).total_duration
    with tempfile.TemporaryDirectory() as tmp:
        if args.segments is not None:
            args.scene = scene_with_segments(args.scene, args.segments, Path(tmp))
        out = Path(tmp) / "demo.mcap"
        plain, recorded = [], []
        for _ in range(args.repeat):  # interleaved, best of each: the machine is shared and noisy
            plain.append(simulate(args.scene, script, None))
            out.unlink(missing_ok=True)  # the recorder never overwrites a recording: the last round's goes
            recorded.append(simulate(args.scene, script, out))
        plain, recorded = min(plain), min(recorded)
        size = out.stat().st_size / 1e6
        segments = load_scene(args.scene).dlo.segments
        print(f"scene {Path(args.scene).stem} ({segments} segments), script {script.name}, {sim_time:.1f} s "
              f"simulated, {size:.2f} MB")
        print(f"simulation alone        {plain:7.2f} s")
        print(f"simulation + recording  {recorded:7.2f} s   ratio {recorded / plain:.3f} (target <= 1.10)")
        cpu_bare, cpu_replay, walls, bares, frozen, inline = [], [], [], [], [], []
        res = None
        for _ in range(args.replays):  # interleaved; medians (the machine is shared and noisy)
            if args.gc == "freeze":
                gc.freeze()
            bares.append(bare_rtf(args.scene, script))
            cpu_bare.append(bare_rtf(args.scene, script, time.thread_time))
            res, per_step = replay_cpu(out)
            cpu_replay.append(per_step)
            walls.append(res.wall_time)
            # the tracker inline, as before it worked behind (an on_step keeps it so: it may read states)
            inline.append(replay(out, verify=True, on_step=_nothing).wall_time)
            if args.gc == "both":  # the same replay once more, as `dlovr replay` runs it
                gc.freeze()
                frozen.append(replay_cpu(out)[1])
            gc.unfreeze()
        assert res is not None
        med = statistics.median
        rtf = res.sim_time / med(walls)
        dt = res.sim_time / res.steps  # the time step (s)
        # bare's CPU seconds per step (dt / its real-time factor) over the replay's
        ratios = [dt / b / r for b, r in zip(cpu_bare, cpu_replay, strict=True)]
        through = [res.sim_time / w / b for w, b in zip(walls, bares, strict=True)]
        print(f"replay --verify         {med(walls):7.2f} s   {rtf:.2f}x real time (wall, median of "
              f"{args.replays}), divergence: {res.divergence}")
        print(f"bare mj_step                       {med(bares):.2f}x real time (wall; the replay's bound)")
        print(f"replay --verify / bare mj_step throughput, wall clock: {med(through):.3f} (rounds "
              f"{', '.join(f'{x:.3f}' for x in through)}; target >= 0.85; the tracker on a second core)")
        inl = [res.sim_time / w / b for w, b in zip(inline, bares, strict=True)]
        print(f"  with the tracker inline, one core: {med(inl):.3f} (rounds "
              f"{', '.join(f'{x:.3f}' for x in inl)})")
        print(f"  the same in CPU time, all threads: {med(ratios):.3f} (rounds "
              f"{', '.join(f'{x:.3f}' for x in ratios)}; {med(cpu_replay) * 1e6:.0f} vs "
              f"{dt / med(cpu_bare) * 1e6:.0f} µs per step (replay vs bare))")
        if frozen:
            fr = [dt / b / r for b, r in zip(cpu_bare, frozen, strict=True)]
            print(f"  the same with gc.freeze() before the replay (as `dlovr replay` does): {med(fr):.3f} "
                  f"(rounds {', '.join(f'{x:.3f}' for x in fr)}; {med(frozen) * 1e6:.0f} µs per step)")
        if args.no_compile:
            return
        src = Path(tmp) / "many"
        src.mkdir()
        for i in range(args.copies):
            shutil.copy(out, src / f"r{i:02d}.mcap")
        for workers in (1, 2):
            dst = Path(tmp) / f"out{workers}"
            t0 = time.perf_counter()
            subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "dlovr",
                    "compile",
                    str(src),
                    "-o",
                    str(dst),
                    "--workers",
                    str(workers),
                ],
                check=True,
                capture_output=True,
            )
            dt = time.perf_counter() - t0
            print(f"compile, {workers} worker(s)    {dt:7.2f} s   {args.copies / dt:.1f} recordings/s")


if __name__ == "__main__":
    main()
