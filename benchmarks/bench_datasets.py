"""Throughput of datasets: ``generate`` episodes per minute per core, with and without cameras, and
``export`` frames per second with cameras, against bare ``mj_step`` measured side by side.

Run: ``.venv/bin/python benchmarks/bench_datasets.py [--program recordings/programs/l_block.program.json]
[--episodes 2] [--size 320x240] [--fps 30]``

In this one process (one core): ``generate`` of ``--episodes`` runs (cable length +-10 %) without
cameras and again with the ``scene`` and ``gripper`` cameras (CPU time, so that other jobs on the
machine count less); ``export`` of the program's demonstration with both cameras (frames/s, and the
rendering's share); and the bare ``mj_step`` of the demonstration's scene (us a step), so that the
figures can be compared across days as ratios.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VARY = ("dlo.length=10%",)


def _cpu() -> float:
    return time.process_time()


def bare_step_us(recording: Path, n: int = 2000) -> float:
    """Bare ``mj_step`` of the recording's embedded scene (us a step, CPU)."""
    import mujoco

    from dlovr.recording import Recording
    from dlovr.recording.replaying import load_embedded_scene
    from dlovr.sim import Simulator

    with tempfile.TemporaryDirectory() as tmp:
        sim = Simulator(load_embedded_scene(Recording(recording), tmp))
    m, d = sim.model, sim.data
    t0 = _cpu()
    for _ in range(n):
        mujoco.mj_step(m, d)
    return (_cpu() - t0) / n * 1e6


def main() -> None:
    from dlovr.datasets import ExportOptions, export
    from dlovr.datasets.generate import generate, trial_setup
    from dlovr.execution.run import find_recording
    from dlovr.model.program import Program

    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--program", default=str(ROOT / "recordings/programs/l_block.program.json"))
    ap.add_argument("--episodes", type=int, default=2)
    ap.add_argument("--size", default="320x240")
    ap.add_argument("--fps", type=float, default=30.0)
    args = ap.parse_args()
    size = tuple(int(x) for x in args.size.split("x"))
    assert len(size) == 2
    rec = find_recording(Program.load(args.program))
    assert rec is not None, "the program's demonstration is needed"
    setup = trial_setup(args.program, VARY, 0)
    print(f"bare mj_step: {bare_step_us(rec):.0f} us a step (CPU)")
    with tempfile.TemporaryDirectory() as tmp:
        for cams in ((), ("scene", "gripper")):
            opts = ExportOptions(fmt="robomimic", fps=args.fps, cameras=cams, size=(size[0], size[1]))
            t0 = _cpu()
            res = generate(setup, args.episodes, Path(tmp) / f"gen{len(cams)}.hdf5", opts)
            cpu = _cpu() - t0
            print(f"generate, cameras {','.join(cams) or 'none'} at {args.size}: {args.episodes} runs, "
                  f"{len(res.kept)} kept, {cpu:.1f} CPU s: {60 * args.episodes / cpu:.1f} episodes/min/core")
        for cams in ((), ("scene", "gripper")):
            opts = ExportOptions(fmt="lerobot", fps=args.fps, cameras=cams, size=(size[0], size[1]))
            t0 = _cpu()
            eps = export([rec], Path(tmp) / f"exp{len(cams)}", opts)
            cpu = _cpu() - t0
            frames = sum(ep.length for ep in eps)
            print(f"export {rec.name}, cameras {','.join(cams) or 'none'} at {args.size}: {frames} frames, "
                  f"{cpu:.1f} CPU s: {frames / cpu:.1f} frames/s")


if __name__ == "__main__":
    main()
