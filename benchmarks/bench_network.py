"""The network target side by side in one run: a network program, the single-demonstration program
and the open-loop replay on the same perturbed peg_in_hole trials.

Run: ``.venv/bin/python benchmarks/bench_network.py [--demos 20] [--from runs|script|people]
[--demo-seed 1] [--person 1] [--keep-chatter | --without-chatter] [--trials 50] [--seed 0] [--workers 2]
[--keep DIR]``

1. the sample demonstration (``recordings/peg_in_hole.mcap``, given first: the network's reference
   demonstration) and ``--demos`` demonstrations, merged into a network (``dlovr network``: the
   chatter of each demonstration a hand made removed; ``--keep-chatter``: kept in all;
   ``--without-chatter``: removed from all) and compiled into a network program (``dlovr compile
   --network``).
   ``--from runs`` (default): recorded runs of the sample program (``dlovr run --trials --record``) in
   scenes perturbed from ``--demo-seed``, a demonstrator who adapts to each scene as a person does;
   ``--from script``: the scripted demonstration replayed open loop in each perturbed scene (``dlovr
   record --trials``, the README's way), which reaches the goal in about a quarter; ``--from people``:
   the script played by the person-like demonstrator (``--vary demo.person=--person``, docs/people.md)
   in the nominal scene;
2. ``--trials`` trials from ``--seed`` (default 0) with the same variation (cable length +-10 %,
   stiffness x0.5-2, friction +-30 %, obstacles +-5 mm): the network program, then the sample program
   with ``--baseline replay``;
3. one table: success rates of the three, the network's size, its probability of reaching the goal
   from the start, and that against the probability the planner gives the reference demonstration's
   own path (the plan must never prefer a less likely path).

Everything goes through the ``dlovr`` command as a user would run it, in a temporary directory (or
``--keep DIR``: the recordings go to ``DIR/demos-FROM-seedK`` and are reused when it holds at least
``--demos`` of them, the first ``--demos`` taken, so the 10- and the 20-demonstration networks share
one set; trials are reused too, the single program's across networks, but only by the same program
file run by the same code: their folder's name ends in a fingerprint of both, :func:`fingerprint`).
About 3 min for 20 demonstrations and 5 min for 50 trials of each on 2 workers.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHATTER = {None: ", chatter removed from the hand-made ones", "keep": ", chatter kept",
           "all": ", chatter removed from all"}
VARY = ("dlo.length=10%", "dlo.young=0.5..2", "dlo.friction=30%", "objects.pos=0.005")


def dlovr(*args: str) -> str:
    r = subprocess.run([sys.executable, "-m", "dlovr", *args], capture_output=True, text=True, cwd=ROOT)
    if r.returncode != 0:
        why = r.stderr.strip() or r.stdout.strip()
        raise SystemExit(f"dlovr {' '.join(args)}: exit {r.returncode}: {why}")
    return r.stdout


def record_demos(a: argparse.Namespace, d: Path, vary: list[str]) -> tuple[list[Path], float]:
    """The ``--demos`` demonstrations (paths), recorded into ``d`` unless it already holds that many
    (then the first ``--demos`` of them are used), and the seconds it took to record them."""
    have = sorted(d.glob("*.mcap"))
    if len(have) >= a.demos:
        return have[: a.demos], 0.0
    t0 = time.perf_counter()
    n, seed, workers = str(a.demos), str(a.demo_seed), str(a.workers)
    if a.source == "script":
        dlovr("record", "--script", "scenes/peg_in_hole.script.toml", "--trials", n, "--seed", seed,
              *vary, "--workers", workers, "--force", "-o", str(d))
    elif a.source == "people":  # the nominal scene, a person's hand (docs/people.md)
        dlovr("record", "--script", "scenes/peg_in_hole.script.toml", "--trials", n, "--seed", seed,
              "--vary", f"demo.person={a.person:g}", "--workers", workers, "--force", "-o", str(d))
    else:
        dlovr("run", "recordings/programs/peg_in_hole.program.json", "--trials", n, "--seed", seed,
              *vary, "--record", "--workers", workers, "-o", str(d))
    return sorted(d.glob("*.mcap"))[: a.demos], time.perf_counter() - t0


def fingerprint(program: str) -> str:
    """12 hex digits of a hash of the program file and of every ``dlovr`` source file: trials kept under
    ``--keep`` are reused only when neither changed (a fix in the executor changes their results)."""
    h = hashlib.sha256((ROOT / program).read_bytes())
    for f in sorted((ROOT / "dlovr").rglob("*.py")):
        h.update(f.relative_to(ROOT).as_posix().encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:12]


def trials(d: Path, program: str, a: argparse.Namespace, vary: list[str], *extra: str) -> tuple[dict, float]:
    """``dlovr run PROGRAM --trials`` into ``d`` + the program's and the code's :func:`fingerprint`
    (its ``summary.json`` reused when there) and the wall s."""
    d = d.with_name(f"{d.name}-{fingerprint(program)}")
    if (d / "summary.json").exists():
        return json.loads((d / "summary.json").read_text()), 0.0
    t0 = time.perf_counter()
    dlovr("run", program, "--trials", str(a.trials), "--seed", str(a.seed), *vary, *extra,
          "--workers", str(a.workers), "-o", str(d))
    return json.loads((d / "summary.json").read_text()), time.perf_counter() - t0


def reference_check(prog_path: Path) -> str:
    """The plan from the start against the reference demonstration's own path: their probabilities
    (docs/networks.md) and whether the plan never prefers a less likely path."""
    from dlovr.model.planning import NetworkProgram, load_runnable, reference_path  # in this process

    prog = load_runnable(prog_path)
    assert isinstance(prog, NetworkProgram)
    net = prog.network
    start = next(p for p in net.starts if p.node == net.start)
    plan = prog.plan_from_start()
    p_plan = plan[0].reach_probability if plan else 0.0
    p_ref = prog.path_probability(reference_path(prog.network), start.position)
    same = [e for ch in plan for e in ch.macro.edges] == list(reference_path(prog.network))
    verdict = "ok" if p_plan >= p_ref else "NOT MET"
    return (f"plan P(goal) {p_plan:.4f} vs the reference's own path {p_ref:.4f}: {verdict}"
            f"{' (the plan is the reference path)' if same else ''}")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--demos", type=int, default=20)
    ap.add_argument("--from", dest="source", choices=("runs", "script", "people"), default="runs")
    ap.add_argument("--demo-seed", type=int, default=1, help="the demonstrations' seed")
    ap.add_argument("--person", type=float, default=1.0, help="--from people: drift and tremor, x defaults")
    chat = ap.add_mutually_exclusive_group()
    chat.add_argument("--keep-chatter", dest="chatter", action="store_const", const="keep",
                      help="dlovr network --keep-chatter")
    chat.add_argument("--without-chatter", dest="chatter", action="store_const", const="all",
                      help="dlovr network --without-chatter")
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0, help="the trials' seed")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", help="the folder for everything (reused)")
    a = ap.parse_args()
    vary = [x for v in VARY for x in ("--vary", v)]
    with tempfile.TemporaryDirectory(prefix="dlovr-bench-network-") as tmp:
        d = Path(a.keep) if a.keep else Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        hand = f"-p{a.person:g}" if a.source == "people" else ""
        demos, t_demos = record_demos(a, d / f"demos-{a.source}{hand}-seed{a.demo_seed}", vary)
        suffix = {"keep": "-chatter", "all": "-nochatter"}.get(a.chatter, "")
        tag = f"{a.source}{hand}-seed{a.demo_seed}-{a.demos}{suffix}"
        net, prog_path = d / f"net-{tag}.json", d / f"net-{tag}.prog.json"
        # the sample demonstration first: the network's reference, whose tracks its macros follow
        dlovr("network", "recordings/peg_in_hole.mcap", *map(str, demos), "-o", str(net), "--force",
              *({"keep": ["--keep-chatter"], "all": ["--without-chatter"]}.get(a.chatter, [])))
        dlovr("compile", "--network", str(net), "-o", str(prog_path), "--force")
        prog = json.loads(prog_path.read_text())
        check = reference_check(prog_path)
        runs = f"{a.trials}-seed{a.seed}"
        netres, t_net = trials(d / f"network-{tag}-{runs}", str(prog_path), a, vary)
        single, t_single = trials(d / f"single-{runs}", "recordings/programs/peg_in_hole.program.json", a,
                                  vary, "--baseline", "replay")
    s = prog["summary"]
    what = {"runs": "recorded program runs", "script": "scripted demonstrations",
            "people": f"person-like demonstrations (demo.person={a.person:g}, nominal scene)"}[a.source]
    print(f"peg_in_hole, {a.trials} trials (seed {a.seed}), the sample + {a.demos} {what} (seed "
          f"{a.demo_seed}){CHATTER[a.chatter]}, {a.workers} workers")
    print(f"network: {s['nodes']} situations, {s['edges']} transitions, P(goal) from the start "
          f"{s['plan_reach_probability']:.3f} over {s['plan_macros']} macros "
          f"({t_demos:.0f} s to record)")
    print(check)
    print(f"{'':24}{'goal reached':>14}{'wall':>9}")
    print(f"{'network program':24}{netres['program_success_rate']:>13.0%}{t_net:>8.0f}s")
    print(f"{'single program':24}{single['program_success_rate']:>13.0%}{t_single:>8.0f}s")
    print(f"{'open-loop replay':24}{single['openloop_success_rate']:>13.0%}{'  same runs':>9}")
    rates = f"{netres['program_success_rate']:.2f} / {single['program_success_rate']:.2f}"
    print(f"network / single program: {rates} (target: network >= 0.9 and >= single)")


if __name__ == "__main__":
    main()
