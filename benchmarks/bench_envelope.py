"""The envelope of a program: program, network program and open-loop replay side by side, per axis of
variation and size, in one command (issue 28).

Run: ``.venv/bin/python benchmarks/bench_envelope.py [--trials 50] [--seed 0] [--workers 2]
[--rows standard,noise] [--network NET.program.json] [--give-way M] [-o envelope/]``

Rows (each ``--trials`` trials from ``--seed``, the same perturbed scenes for every column of a row):

- ``standard``: the documented variation (cable length +-10 %, stiffness x0.5-2, friction +-30 %,
  obstacles +-5 mm, docs/programs.md);
- ``noise 0.01`` / ``0.02`` / ``0.05``: the same with that white force noise (N, ``--noise``);
- ``shift 5`` / ``10`` / ``15`` mm: the objects shifted together (``objects.pos``), blind and
  registered (``--registered``: the executor is told where they are);
- ``turn 5`` / ``10`` deg: the objects turned together about the vertical (``objects.yaw``), blind
  and registered (the executor also told their turns);
- ``gripper+young``: the gripper's start +-5 mm and the stiffness x0.3-3;
- each ``--vary`` key alone at two sizes (``dlo.length`` 5 / 10 %, ...).

Columns: the program blind, the program registered (rows that move objects), the network program
(``--network``: a network program, e.g. from ``bench_network.py --keep DIR``; blind, and registered
on rows that move objects), with ``--replan`` the
blind program recovering through that network where its goal check says it missed the goal
(:mod:`dlovr.execution.recovery`), the replay of the
demonstration's commands open loop, the program's false detections over the macros it ran, and
how the sensed goal check judged the blind runs (missed goals it caught, reached goals it doubted).
``-o DIR`` gets ``envelope.md`` (the table), ``envelope.json`` and ``envelope.png`` (success rate
per row). ``--rows`` keeps the rows whose name contains one of the given words; ``--trials 5`` for a
quick look; ``--no-replay``, ``--blind-only`` and ``--network-only`` (only the network program) leave
columns out; ``--give-way M`` runs the programs as ``dlovr run --give-way M`` does (the replay is
unchanged). The trials run through
:func:`dlovr.execution.trials.run_trials` on ``--workers`` local processes.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dlovr.execution.demo_track import load_track
from dlovr.execution.executor import ExecOptions
from dlovr.execution.recovery import Recovery
from dlovr.execution.run import find_recording, resolve_scene
from dlovr.execution.trials import TrialSetup, goal_check_counts, replan_counts, run_trials
from dlovr.execution.variation import parse_varies
from dlovr.geometry import scene_pieces
from dlovr.model.planning import load_runnable
from dlovr.model.program import Program

ROOT = Path(__file__).resolve().parents[1]
STANDARD = ("dlo.length=10%", "dlo.young=0.5..2", "dlo.friction=30%", "objects.pos=0.005")
#: each key alone at two sizes
SINGLE = (
    ("dlo.length", "5%", "10%"),
    ("dlo.radius", "5%", "10%"),
    ("dlo.young", "0.7..1.4", "0.5..2"),
    ("dlo.damping", "0.7..1.4", "0.5..2"),
    ("dlo.mass", "10%", "20%"),
    ("dlo.friction", "15%", "30%"),
    ("gripper.pos", "0.0025", "0.005"),
    ("objects.pos", "0.0025", "0.005"),
)


@dataclass(frozen=True)
class Row:
    """One row: its name, the ``--vary`` items, the force noise (N) and whether objects move (then the
    program also runs registered)."""

    name: str
    vary: tuple[str, ...]
    noise: float = 0.0

    @property
    def moves_objects(self) -> bool:
        return any(v.startswith("objects.") for v in self.vary)


def rows() -> list[Row]:
    out = [Row("standard", STANDARD)]
    out += [Row(f"standard + noise {n:g} N", STANDARD, n) for n in (0.01, 0.02, 0.05)]
    out += [Row(f"shift {mm} mm", (f"objects.pos={mm / 1000:g}",)) for mm in (5, 10, 15)]
    out += [Row(f"turn {deg} deg", (f"objects.yaw={deg}",)) for deg in (5, 10)]
    out += [Row("gripper+young", ("gripper.pos=0.005", "dlo.young=0.3..3"))]
    out += [Row(f"{key} {size}", (f"{key}={size}",)) for key, a, b in SINGLE for size in (a, b)]
    return out


def _rate(trials: list[dict[str, Any]], key: str) -> float:
    if key == "openloop":
        return sum(bool(t["openloop"]["goal_reached"]) for t in trials) / len(trials)
    return sum(bool(t["program"]["success"]) for t in trials) / len(trials)


def _false(trials: list[dict[str, Any]]) -> tuple[int, int]:
    macros = [m for t in trials for m in t["program"]["macros"] if m["outcome"] != "not run"]
    return sum(m["outcome"] == "false" for m in macros), len(macros)


def run_row(row: Row, base: dict[str, Any], args: argparse.Namespace) -> dict[str, Any]:
    """The row's columns: blind program with the replay, registered program, network program."""
    scene = base["scene"]
    variations = parse_varies(row.vary, scene)
    opts = ExecOptions(noise=row.noise, give_way=args.give_way)
    common = dict(scene=scene, pieces=base["pieces"], variations=variations, seed=args.seed, opts=opts)
    out: dict[str, Any] = {"row": row.name, "vary": list(row.vary), "noise_n": row.noise,
                           "trials": args.trials, "seed": args.seed}
    t0 = time.perf_counter()
    if not args.network_only:
        out.update(_blind(base, common, args))
    if row.moves_objects and not args.blind_only and not args.network_only:
        reg = run_trials(TrialSetup(program=base["program"], track=base["track"], registered=True, **common),
                         args.trials, workers=args.workers)
        out["registered"] = _rate(reg, "program")
        out["false_registered"] = _false(reg)[0]
    if base["network"] is not None and args.replan:
        rec = Recovery(base["network"])
        again = run_trials(TrialSetup(program=base["program"], track=base["track"], recovery=rec, **common),
                           args.trials, workers=args.workers)
        out["replan"] = _rate(again, "program")
        out["replans"] = replan_counts(again)
    if base["network"] is not None and not args.replan_only:
        net = run_trials(TrialSetup(program=base["network"], track=None, use_track=False, **common),
                         args.trials, workers=args.workers)
        out["network"] = _rate(net, "program")
        if row.moves_objects and not args.blind_only:
            net = run_trials(TrialSetup(program=base["network"], track=None, use_track=False, registered=True,
                                        **common), args.trials, workers=args.workers)
            out["network_registered"] = _rate(net, "program")
    out["wall_s"] = round(time.perf_counter() - t0, 1)
    return out


def _blind(base: dict[str, Any], common: dict[str, Any], args: argparse.Namespace) -> dict[str, Any]:
    """The blind program's columns (with the replay's unless ``--no-replay``)."""
    replay = not args.no_replay
    blind = run_trials(TrialSetup(program=base["program"], track=base["track"], baseline=replay, **common),
                       args.trials, workers=args.workers)
    failed = [t["program"] for t in blind if not t["program"]["success"]]
    n_false, n_macros = _false(blind)
    return {"program": _rate(blind, "program"), "replay": _rate(blind, "openloop") if replay else None,
            "false": n_false, "macros": n_macros, "goal_check": goal_check_counts(blind),
            "first_deviations": [p.get("first_deviation") for p in failed],
            "failed_trials": [t["trial"] for t in blind if not t["program"]["success"]]}


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{x:.0%}"


def _check_text(g: dict[str, int] | None) -> str:
    if not g:
        return "-"
    return f"caught {g['caught']} of {g['missed']} missed, doubted {g['doubted']} of {g['reached']} reached"


def _below(program: float | None, replay: float | None) -> bool:
    return program is not None and replay is not None and program < replay


def table(results: list[dict[str, Any]]) -> str:
    lines = ["| row | program (blind) | registered | blind + replan | network | network registered | replay "
             "| false detections | goal check |", "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        below = " **below replay**" if _below(r.get("program"), r.get("replay")) else ""
        n_false, n_macros = r.get("false", 0), max(r.get("macros", 0), 1)
        fd = "-" if "false" not in r else f"{n_false} of {r['macros']} ({n_false / n_macros:.1%})"
        cells = [f"{r['row']} ({r['trials']} trials, seed {r['seed']})", f"{_pct(r.get('program'))}{below}",
                 _pct(r.get("registered")), _pct(r.get("replan")), _pct(r.get("network")),
                 _pct(r.get("network_registered")), _pct(r.get("replay")), fd,
                 _check_text(r.get("goal_check"))]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(results: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = [("program", "program (blind)", "tab:blue"), ("registered", "registered", "tab:green"),
            ("replan", "blind + replan", "tab:red"), ("network", "network", "tab:purple"),
            ("network_registered", "network registered", "tab:pink"), ("replay", "replay", "tab:orange")]
    fig, ax = plt.subplots(figsize=(max(6.0, 0.55 * len(results) + 2), 4.0))
    w = 0.13
    for k, (key, label, color) in enumerate(cols):
        xs = [i + (k - 2.5) * w for i, r in enumerate(results) if r.get(key) is not None]
        ys = [r[key] for r in results if r.get(key) is not None]
        if ys:
            ax.bar(xs, ys, width=w, label=label, color=color)
    ax.set_xticks(range(len(results)), [r["row"] for r in results], rotation=60, ha="right", fontsize=7)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("goal reached (fraction of trials)")
    ax.legend(fontsize=7)
    n = results[0]["trials"] if results else 0
    ax.set_title(f"envelope: {n} trials a row, seed {results[0]['seed'] if results else 0}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--program", default=str(ROOT / "recordings/programs/peg_in_hole.program.json"))
    ap.add_argument("--network", help="a network program to run beside it")
    ap.add_argument("--replan", action="store_true",
                    help="with --network: also the blind program recovering through it (a column)")
    ap.add_argument("--replan-only", action="store_true",
                    help="with --replan: leave the network program's own column out (faster)")
    ap.add_argument("--network-only", action="store_true",
                    help="with --network: only the network program's column (the blind program's left out)")
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--rows", help="comma-separated words: keep the rows whose name contains one")
    ap.add_argument("--no-replay", action="store_true", help="leave the open-loop replay out (faster)")
    ap.add_argument("--blind-only", action="store_true", help="leave the registered runs out (faster)")
    ap.add_argument("--give-way", type=float, default=None, metavar="M",
                    help="run the programs with dlovr run --give-way M (m; default: dlovr run's)")
    ap.add_argument("-o", "--output", default="envelope")
    args = ap.parse_args()

    program = Program.load(args.program)
    rec = find_recording(program)
    if rec is None:
        raise SystemExit(f"{args.program}: its demonstration was not found")
    scene = resolve_scene(program, None, rec)
    network = load_runnable(args.network) if args.network else None
    base = {"program": program, "scene": scene, "pieces": scene_pieces(scene), "track": load_track(rec),
            "network": network}
    keep = [w.strip() for w in args.rows.split(",")] if args.rows else None
    todo = [r for r in rows() if keep is None or any(w in r.name for w in keep)]
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    results: list[dict[str, Any]] = []
    for row in todo:
        results.append(run_row(row, base, args))
        r = results[-1]
        print(f"{row.name}: program {_pct(r.get('program'))}, registered {_pct(r.get('registered'))}, "
              f"replan {_pct(r.get('replan'))}, network {_pct(r.get('network'))} "
              f"(registered {_pct(r.get('network_registered'))}), "
              f"replay {_pct(r.get('replay'))}, "
              f"false {r.get('false', '-')}/{r.get('macros', '-')} ({r['wall_s']} s)", flush=True)
        (out / "envelope.json").write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    text = table(results)
    (out / "envelope.md").write_text(text + "\n", encoding="utf-8")
    plot(results, out / "envelope.png")
    print(text)
    print(f"results in {out}/ (envelope.md, envelope.json, envelope.png)")


if __name__ == "__main__":
    main()
