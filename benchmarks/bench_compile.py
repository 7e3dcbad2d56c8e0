"""First-run kernel compilation vs loading the cached kernels, side by side in one run.

Run: ``.venv/bin/python benchmarks/bench_compile.py [--steps 1000] [--scene peg_in_hole]``

Starts a fresh Python process three times, with a new, empty kernel store (``$DLOVR_CACHE_DIR``, a
temporary directory) and numba cache directory (``$NUMBA_CACHE_DIR``: numba's cache in ``__pycache__``
beside the sources is not consulted when it is set, and the "kernels warm" marker lives beside
numba's cache, so the first process finds nothing):

1. first run: the kernels compile (target: at most 10 s), and go into the kernel store;
2. cached run: the same on the cache the first run wrote;
3. new installation: another empty numba cache directory (as a new virtual environment has), the
   kernels copied from the store (:func:`dlovr.jit.keep_in_store`) instead of compiled.

Each process times what ``dlovr serve`` / ``dlovr demo`` do before their first step: importing numba
and the kernel modules, then :func:`dlovr.sim.warmup.warm_up` (the part behind "compiling kernels
(first run only)"), then ``--steps`` steps of the scene's built-in demonstration with contact-state
extraction. Wall-clock seconds, with the process's CPU seconds beside them (compilation runs on one
core: on a shared machine the CPU time leaves out the time other processes held it).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

_CHILD = r"""
import json, sys, time
w0, c0 = time.perf_counter(), time.process_time()
def lap():
    global w0, c0
    w, c = time.perf_counter(), time.process_time()
    out = (w - w0, c - c0)
    w0, c0 = w, c
    return out
import numba  # noqa: F401
t_numba = lap()
from dlovr.sim import kernels, track_kernels  # noqa: F401
from dlovr.geometry import kernels as gk  # noqa: F401
from dlovr.sim.warmup import warm_up
t_import = lap()
warm_up()
t_warm = lap()
from dlovr.scene import load_scene, scenes_dir
from dlovr.script import load_script
from dlovr.sim import Simulator
script = load_script(scenes_dir() / f"{sys.argv[1]}.script.toml")
sim = Simulator(load_scene(script.scene or sys.argv[1]), track=True)
n = 0
for rec in sim.run(script):
    n += 1
    if n >= int(sys.argv[2]):
        break
t_sim = lap()
print(json.dumps({"numba": t_numba, "import": t_import, "warm_up": t_warm, "sim": t_sim}))
"""

_ROWS = (
    ("import numba", "numba"),
    ("import kernel modules", "import"),
    ("warm_up (compile or load)", "warm_up"),
    ("first steps", "sim"),
)


def _run(cache: Path, store: Path, scene: str, steps: int) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), DLOVR_CACHE_DIR=str(store))
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, scene, str(steps)], env=env, check=True, capture_output=True, text=True
    )
    times = json.loads(out.stdout.strip().splitlines()[-1])
    times["process"] = (time.perf_counter() - t0, None)
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--scene", default="peg_in_hole", help="built-in scene whose script is stepped")
    ap.add_argument("--steps", type=int, default=1000, help="steps simulated after the warm-up")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="dlovr-bench-compile-") as tmp:
        numba_cache, other_cache, store = Path(tmp, "numba"), Path(tmp, "numba-new"), Path(tmp, "store")
        first = _run(numba_cache, store, args.scene, args.steps)
        cached = _run(numba_cache, store, args.scene, args.steps)
        stored = _run(other_cache, store, args.scene, args.steps)
    print(f"numba {__import__('numba').__version__}, NUMBA_OPT={os.environ.get('NUMBA_OPT', '(default)')}, "
          f"{args.steps} steps of {args.scene}; seconds wall (CPU)")
    print(f"{'':28} {'first run':>16} {'cached':>16} {'from the store':>16}")

    def cell(t: tuple) -> str:
        return f"{t[0]:7.2f}" + (f" ({t[1]:6.2f})" if t[1] is not None else " " * 9)

    for label, key in (*_ROWS, ("whole process", "process")):
        print(f"{label:28} {cell(first[key]):>16} {cell(cached[key]):>16} {cell(stored[key]):>16}")


if __name__ == "__main__":
    main()
