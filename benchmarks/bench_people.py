"""Programs from person-like demonstrations against the scripted program and their own replays.

Run: ``.venv/bin/python benchmarks/bench_people.py [--scripts peg_in_hole ...] [--demos 5] [--trials 20]
[--person 1] [--seed 0] [--workers 1] [--out DIR] [--calibrate] [--give-way M]``

For each built-in script (``scenes/NAME.script.toml``): ``--demos`` demonstrations played by the
person-like demonstrator (docs/people.md; ``--person 2``: twice the default drift and tremor), recorded
with seed ``--seed`` and compiled; each program's class sequence against the sample scripted program's
(``recordings/programs/NAME.program.json``: edit distance over the macros' class labels), its macro
count against the scripted one's, and, with ``--trials`` > 0, how often the program and its open-loop
replay reach the goal under the standard variation (cable length +-10 %, stiffness x0.5-2, friction
+-30 %, obstacles +-5 mm; trial seed 0). One table, one row a demonstration, then the totals per
script. The recordings stay in ``--out`` (default: a temporary folder). With ``--calibrate`` each
program is compiled as ``dlovr compile --calibrate`` compiles it (its detections without force signal
calibrated in simulation, docs/programs.md "Calibrated detection"; 2-4 min a demonstration), and
``cal`` gives how many of its macros were calibrated of those without force signal. ``--give-way M``
runs the programs as ``dlovr run --give-way M`` does (default: as ``dlovr run`` does, 5 mm for these
programs of a hand's demonstrations; the replays are unchanged).

For peg-in-hole each row also gives ``corner``: how much of the drag along the groove (the gripper's
travel along -y, mm) is left when the tip reaches the groove's corner (``V/VI``), as recorded and as
the program follows it (the track averaged to take out the tremor): what decides whether the tip
goes over the corner into the hole (docs/people.md, "Why these programs fail").
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from dlovr.execution.calibration import calibrate_recording
from dlovr.execution.demo_sets import DemoSetup, demo_path, record_demos
from dlovr.execution.demo_track import load_track
from dlovr.execution.executor import ExecOptions
from dlovr.execution.motion import HAND_GIVE_WAY_M
from dlovr.execution.run import resolve_scene
from dlovr.execution.trials import TrialSetup, run_trials
from dlovr.execution.variation import parse_varies
from dlovr.geometry import scene_pieces
from dlovr.model.margins import blind
from dlovr.model.program import Program
from dlovr.model.smoothing import TREMOR_ACCEL, smooth_poses, tremor_of
from dlovr.recording.bundle import SceneBundle
from dlovr.recording.compile import compile_recording
from dlovr.recording.reader import Recording, kept_states
from dlovr.scene import load_scene
from dlovr.script import load_script

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = ("table", "edges", "peg_in_hole", "l_block", "corners")
VARY = ("dlo.length=10%", "dlo.young=0.5..2", "dlo.friction=30%", "objects.pos=0.005")


def labels(program: Program) -> list[str]:
    return [m.label for m in program.macros]


def edit_distance(a: list[str], b: list[str]) -> int:
    """Levenshtein distance between two label sequences."""
    row = list(range(len(b) + 1))
    for i, x in enumerate(a, 1):
        prev, row[0] = row[0], i
        for j, y in enumerate(b, 1):
            prev, row[j] = row[j], min(row[j] + 1, row[j - 1] + 1, prev + (x != y))
    return row[-1]


def record(name: str, args: argparse.Namespace, out: Path) -> list[Path]:
    script = load_script(ROOT / "scenes" / f"{name}.script.toml")
    scene = load_scene(script.scene or name)
    setup = DemoSetup(scene, scene_pieces(scene), script,
                      parse_varies([f"demo.person={args.person:g}"], scene, demo=True), args.seed,
                      str(out.resolve()), SceneBundle.from_path(scene.path).digest)
    todo = [k for k in range(args.demos) if not demo_path(setup, k).exists()]
    if todo:
        record_demos(setup, args.demos, workers=args.workers)
    return [demo_path(setup, k) for k in range(args.demos)]


def success(program: Program, rec: Path, args: argparse.Namespace) -> tuple[float, float]:
    """How often the program and its replay reach the goal in ``--trials`` standard-variation trials."""
    scene = resolve_scene(program, None, rec)
    setup = TrialSetup(program=program, scene=scene, pieces=scene_pieces(scene), track=load_track(rec),
                       variations=parse_varies(VARY, scene), seed=0, opts=ExecOptions(give_way=args.give_way),
                       baseline=True)
    trials = run_trials(setup, args.trials, workers=args.workers)
    prog = sum(bool(t["program"]["success"]) for t in trials) / len(trials)
    replay = sum(bool(t.get("openloop", {}).get("goal_reached")) for t in trials) / len(trials)
    return prog, replay


def corner_margin(rec: Path) -> str:
    """Peg-in-hole: the drag left (mm, gripper -y) when the tip reaches the groove's corner, as
    recorded / as the program follows it ("-" without a ``V/VI`` situation)."""
    r = Recording(rec)
    steps, pos, quat = r.commands()
    t = np.asarray(steps, dtype=float) * r.dt
    at = [k.t for k in kept_states(r, None) if "V/VI[" in k.situation.format()]
    if not at:
        return "-"
    i = int(np.searchsorted(t, at[0]))
    near = (t > at[0] - 3.0) & (t < at[0] + 1.0)
    follows = smooth_poses(t, pos, quat)[0] if tremor_of(t, pos) > TREMOR_ACCEL else pos
    left = [1000.0 * (p[i, 1] - p[near, 1].min()) for p in (pos, follows)]
    return f"{left[0]:.1f}/{left[1]:.1f}"


def _compiled(rec: Path, calibrate: bool) -> tuple[Program, str]:
    """The recording's program (calibrated with ``calibrate``) and how many of its macros without
    force signal were calibrated (``K/N``; "-" uncalibrated)."""
    prog = compile_recording(rec)
    if not calibrate:
        return prog, "-"
    weak = sum(blind(m, ExecOptions().min_snr) for m in prog.classed)
    prog = calibrate_recording(prog, rec)
    done = sum(any(d.derivation.get("step_n", "").startswith("calibrated") for d in m.detection)
               for m in prog.classed)
    return prog, f"{done}/{weak}"


def _pct(x: float) -> str:
    return "-" if x != x else f"{x:.0%}"  # NaN: no trials run


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--scripts", nargs="+", default=list(SCRIPTS), choices=SCRIPTS)
    ap.add_argument("--demos", type=int, default=5)
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--person", type=float, default=1.0, help="drift and tremor, times the defaults")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--out", help="folder for the recordings (kept; reused when there)")
    ap.add_argument("--calibrate", action="store_true",
                    help="calibrate the programs (dlovr compile --calibrate)")
    ap.add_argument("--give-way", type=float, default=None, metavar="M",
                    help="run the programs with dlovr run --give-way M (m; default: dlovr run's)")
    args = ap.parse_args()
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_people_"))
    way = f"{args.give_way:g} m" if args.give_way is not None else f"{HAND_GIVE_WAY_M:g} m (a hand's default)"
    print(f"{args.demos} demonstrations a script, demo.person={args.person:g}, seed {args.seed}, "
          f"{args.trials} trials each (seed 0, {' '.join(VARY)}), give-way {way}; "
          f"recordings in {out}")
    print(f"{'script':<12} {'demo':>4} {'macros':>6} {'ratio':>5} {'edit':>4} {'same':>4} "
          f"{'program':>7} {'replay':>6} {'corner':>9} {'cal':>5}  classes")
    for name in args.scripts:
        t0 = time.perf_counter()
        ref = Program.load(ROOT / "recordings" / "programs" / f"{name}.program.json")
        rows = []
        for k, rec in enumerate(record(name, args, out / name)):
            prog, cal = _compiled(rec, args.calibrate)
            dist = edit_distance(labels(prog), labels(ref))
            ok, replay = success(prog, rec, args) if args.trials > 0 else (float("nan"), float("nan"))
            rows.append((len(prog.macros), dist, ok, replay))
            corner = corner_margin(rec) if name == "peg_in_hole" else ""
            print(f"{name:<12} {k:>4} {len(prog.macros):>6} {len(prog.macros) / len(ref.macros):>5.2f} "
                  f"{dist:>4} {'yes' if dist == 0 else 'no':>4} {_pct(ok):>7} {_pct(replay):>6} "
                  f"{corner:>9} {cal:>5}  {' '.join(labels(prog))}", flush=True)
        same = sum(r[1] == 0 for r in rows)
        worst = max(r[0] for r in rows) / len(ref.macros)
        mean_ok = sum(r[2] for r in rows) / len(rows)
        mean_replay = sum(r[3] for r in rows) / len(rows)
        print(f"{name:<12}  all: scripted {len(ref.macros)} macros ({' '.join(labels(ref))}); classes "
              f"equal in {same}/{len(rows)}, macros <= {worst:.2f}x, program {_pct(mean_ok)} vs replay "
              f"{_pct(mean_replay)} ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
