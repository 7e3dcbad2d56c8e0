"""Bit-identity check of the per-step pipeline: every step's states, forces and raw contacts over
every built-in script and the benchmarks' contact-rich scenes (``benchmarks/scenes/``), saved from
one checkout and compared against another.

Run: ``python benchmarks/check_states.py save REF.pkl`` on the reference checkout, then
``python benchmarks/check_states.py compare REF.pkl`` on the changed one (``--only NAME`` for one
script, ``--segments 40 80`` for extra runs of the peg-in-hole demonstration at those segment counts;
``--programs peg_in_hole --trials 0 1`` for runs of the sample programs through the executor on
``bench_trials.py``'s perturbed scenes, trial 1 with 0.05 N of sensor noise, each followed by its
open-loop replay: every step's record and state, the events and both results).

Per step it keeps: the topological and discrete situation (their notation and the objects
themselves, with the annotations their equality leaves out: DLO vectors, spans, the gripper's z), the
per-contact forces, the gripper force, the cable points and every field of the raw
contact arrays (as bytes), plus the tracker's changes, kept situations and labelling counts at the
end. ``compare`` names the first step that differs. Speeding the pipeline up must change none of it.
"""

from __future__ import annotations

import argparse
import hashlib
import pickle
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from dlovr.scene import load_scene, scenes_dir
from dlovr.script import load_script
from dlovr.sim import Simulator

_FIELDS = ("point", "segment", "geom", "obj", "piece", "dist", "normal", "pos", "force", "active",
           "self_pairs")


def _step_digest(rec) -> tuple:
    st = rec.state
    h = hashlib.sha256(np.ascontiguousarray(rec.points).tobytes())
    h.update(np.ascontiguousarray(rec.gripper_force).tobytes())
    a = rec.contact_arrays
    for f in _FIELDS:
        h.update(np.ascontiguousarray(getattr(a, f)).astype(bool if f == "active" else np.float64).tobytes())
    for c in st.topological.contacts:  # the annotations equality leaves out: vectors, G's z
        h.update(repr((c.dlo.index, c.dlo.span, c.dlo.vector, [e.z for e in c.env])).encode())
    for c in st.discrete.contacts:
        h.update(repr(c.vector).encode())
    return (
        rec.step,
        st.topological.format(),
        st.discrete.format(),
        (st.topological, st.discrete),
        st.forces,
        h.hexdigest(),
    )


def run_program(name: str, trial: int) -> dict:
    """Sample program ``name`` through the executor on trial ``trial``'s perturbed scene, then its
    open-loop replay: every step's digest, the events and both results (wall times left out)."""
    from dlovr.execution.demo_track import load_track
    from dlovr.execution.executor import ExecOptions
    from dlovr.execution.run import find_recording, resolve_scene
    from dlovr.execution.run import run_openloop as openloop
    from dlovr.execution.run import run_program as program_run
    from dlovr.execution.variation import parse_vary, perturb
    from dlovr.geometry import scene_pieces
    from dlovr.model.program import Program

    root = Path(__file__).resolve().parents[1]
    program = Program.load(root / "recordings" / "programs" / f"{name}.program.json")
    rec = find_recording(program)
    base = resolve_scene(program, None, rec)
    track = load_track(rec) if rec is not None else None
    pieces = scene_pieces(base)
    vary = ("dlo.length=10%", "dlo.young=0.5..2", "dlo.friction=30%", "objects.pos=0.005")
    scene, _ = perturb(base, tuple(parse_vary(v, base) for v in vary), 0, trial)
    opts = ExecOptions(seed=trial, noise=0.05 if trial % 2 else 0.0)
    steps: list[tuple] = []
    events: list = []
    t0 = time.perf_counter()
    res = program_run(program, scene, opts, track=track, pieces=pieces,
                      on_step=lambda r: steps.append(_step_digest(r)), on_event=events.append)
    wall = time.perf_counter() - t0
    result = {k: v for k, v in res.to_json().items() if "wall" not in k}
    loop = None
    if track is not None:
        replay = openloop(program, scene, track, pieces=pieces).to_json()
        loop = {k: v for k, v in replay.items() if "wall" not in k}
    end = ([e.payload() for e in events], repr(result), repr(loop), 0, 0)
    return {"steps": steps, "end": end, "wall": wall}


def _same(a: tuple, b: tuple) -> bool:
    """Two steps' digests agree (situations compared by value; a saved one may be pickled)."""
    sa, sb = (pickle.loads(x[3]) if isinstance(x[3], bytes) else x[3] for x in (a, b))
    return a[:3] == b[:3] and a[4:] == b[4:] and sa == sb


def run(name: str, segments: int | None) -> dict:
    script = load_script(_script_path(name))
    scene = load_scene(script.scene or name)
    if segments is not None:
        scene = replace(scene, dlo=replace(scene.dlo, segments=segments))
    sim = Simulator(scene, track=True)
    t0 = time.perf_counter()
    steps = [_step_digest(rec) for rec in sim.run(script)]
    wall = time.perf_counter() - t0
    tr = sim.tracker
    end = (
        [(c.step, c.topological.format(), c.discrete.format(), c.forces) for c in tr.changes],
        [(k.situation.format(), k.start, k.end) for k in tr.kept],
        tr.labellings,
        tr.partial_labellings,
    )
    return {"steps": steps, "end": end, "wall": wall}


BENCH_SCENES = Path(__file__).resolve().parent / "scenes"


def _script_path(name: str) -> Path:
    """A built-in script, or one of the benchmarks' contact-rich scenes (benchmarks/scenes/)."""
    own = BENCH_SCENES / f"{name}.script.toml"
    return own if own.is_file() else scenes_dir() / f"{name}.script.toml"


def _runs(args) -> list[tuple[str, int | None]]:
    names = sorted(p.name.removesuffix(".script.toml") for p in scenes_dir().glob("*.script.toml"))
    names += sorted(p.name.removesuffix(".script.toml") for p in BENCH_SCENES.glob("*.script.toml"))
    runs: list[tuple[str, int | None]] = [(n, None) for n in names]
    runs += [("peg_in_hole", s) for s in args.segments]
    runs += [(f"program:{p}", k) for p in args.programs for k in args.trials]
    if args.only:
        runs = [r for r in runs if r[0] in args.only]
    return runs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("save", "compare"))
    ap.add_argument("ref", type=Path)
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--segments", type=int, nargs="*", default=[40, 80])
    ap.add_argument("--programs", nargs="*", default=[], help="sample programs run through the executor")
    ap.add_argument("--trials", type=int, nargs="*", default=[0, 1], help="their trials (perturbed scenes)")
    args = ap.parse_args()
    out = {} if args.mode == "save" else pickle.loads(args.ref.read_bytes())
    bad = 0
    for name, seg in _runs(args):
        if name.startswith("program:"):
            key = f"{name}#{seg}"
            got = run_program(name.removeprefix("program:"), int(seg or 0))
        else:
            key = f"{name}@{seg or 'scene'}"
            got = run(name, seg)
        n = len(got["steps"])
        if args.mode == "save":
            out[key] = got
            print(f"{key}: {n} steps, {got['wall'] / n * 1e6:.0f} µs/step, saved")
            continue
        want = out.get(key)
        if want is None:
            print(f"{key}: no reference")
            continue
        diff = next(
            (i for i, (a, b) in enumerate(zip(want["steps"], got["steps"], strict=False)) if not _same(a, b)),
            None,
        )
        if diff is None and len(want["steps"]) != n:
            diff = min(len(want["steps"]), n)
        if diff is not None:
            bad += 1
            a = want["steps"][diff] if diff < len(want["steps"]) else None
            b = got["steps"][diff] if diff < n else None
            print(f"{key}: DIFFERS at step index {diff}:")
            print(f"  ref {a and a[:3] + a[4:]}\n  now {b and b[:3] + b[4:]}")
        elif want["end"] != got["end"]:
            bad += 1
            print(f"{key}: steps identical, end differs: ref {want['end'][2:]} now {got['end'][2:]}")
        else:
            ratio = got["wall"] / want["wall"]
            us = got["wall"] / n * 1e6
            print(f"{key}: {n} steps identical ({us:.0f} µs/step, {ratio:.2f}x the reference's)")
    if args.mode == "save":
        args.ref.write_bytes(pickle.dumps(out, protocol=5))
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
