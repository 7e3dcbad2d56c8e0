"""The network target side by side in one run: a network program, the single-demonstration program
and the open-loop replay on the same perturbed peg_in_hole trials.

Run: ``.venv/bin/python benchmarks/bench_network.py [--demos 20] [--from runs|script] [--trials 50]
[--seed 0] [--workers 2] [--keep DIR]``

1. the sample demonstration (``recordings/peg_in_hole.mcap``, given first: the network's reference
   demonstration) and ``--demos`` demonstrations in scenes perturbed from seed 1, merged into a
   network (``dlovr network``) and compiled into a network program (``dlovr compile --network``).
   ``--from runs`` (default): recorded runs of the sample program (``dlovr run --trials --record``),
   a demonstrator who adapts to each scene as a person does; ``--from script``: the scripted
   demonstration replayed open loop in each scene (``dlovr record --trials``), which reaches the
   goal in about a quarter;
2. ``--trials`` trials from ``--seed`` (default 0; the demonstrations' scenes come from seed 1) with the
   same variation (cable length +-10 %, stiffness x0.5-2, friction +-30 %, obstacles +-5 mm): the
   network program, then the sample program with ``--baseline replay``;
3. one table: success rates of the three, the network's size and its probability of reaching the goal
   from the start.

Everything goes through the ``dlovr`` command as a user would run it, in a temporary directory (or
``--keep DIR``). About 3 min for 20 demonstrations and 5 min for 50 trials of each on 2 workers.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VARY = ("dlo.length=10%", "dlo.young=0.5..2", "dlo.friction=30%", "objects.pos=0.005")


def dlovr(*args: str) -> str:
    r = subprocess.run([sys.executable, "-m", "dlovr", *args], capture_output=True, text=True, cwd=ROOT)
    if r.returncode != 0:
        why = r.stderr.strip() or r.stdout.strip()
        raise SystemExit(f"dlovr {' '.join(args)}: exit {r.returncode}: {why}")
    return r.stdout


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--demos", type=int, default=20)
    ap.add_argument("--from", dest="source", choices=("runs", "script"), default="runs")
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0, help="the trials' seed (the demonstrations': 1)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", help="write everything here instead of a temporary directory")
    a = ap.parse_args()
    vary = [x for v in VARY for x in ("--vary", v)]
    with tempfile.TemporaryDirectory(prefix="dlovr-bench-network-") as tmp:
        d = Path(a.keep) if a.keep else Path(tmp)
        d.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        if a.source == "script":
            dlovr("record", "--script", "scenes/peg_in_hole.script.toml", "--trials", str(a.demos),
                  "--seed", "1", *vary, "--workers", str(a.workers), "--force",
                  "-o", str(d / "demos"))
        else:
            dlovr("run", "recordings/programs/peg_in_hole.program.json", "--trials", str(a.demos),
                  "--seed", "1", *vary, "--record", "--workers", str(a.workers),
                  "-o", str(d / "demos"))
        t_demos = time.perf_counter() - t0
        # the sample demonstration first: the network's reference, whose tracks its macros follow
        dlovr("network", "recordings/peg_in_hole.mcap", str(d / "demos"), "-o", str(d / "net.json"))
        dlovr("compile", "--network", str(d / "net.json"), "-o", str(d / "net.prog.json"))
        prog = json.loads((d / "net.prog.json").read_text())
        t0 = time.perf_counter()
        dlovr("run", str(d / "net.prog.json"), "--trials", str(a.trials), "--seed", str(a.seed), *vary,
              "--workers", str(a.workers), "-o", str(d / "network"))
        t_net = time.perf_counter() - t0
        t0 = time.perf_counter()
        dlovr("run", "recordings/programs/peg_in_hole.program.json", "--trials", str(a.trials),
              "--seed", str(a.seed), *vary, "--baseline", "replay", "--workers", str(a.workers),
              "-o", str(d / "single"))
        t_single = time.perf_counter() - t0
        net = json.loads((d / "network" / "summary.json").read_text())
        single = json.loads((d / "single" / "summary.json").read_text())
    s = prog["summary"]
    what = "recorded program runs" if a.source == "runs" else "scripted demonstrations"
    print(f"peg_in_hole, {a.trials} trials (seed {a.seed}), {a.demos} {what} (seed 1), {a.workers} workers")
    print(f"network: {s['nodes']} situations, {s['edges']} transitions, P(goal) from the start "
          f"{s['plan_reach_probability']:.3f} over {s['plan_macros']} macros "
          f"({t_demos:.0f} s to record)")
    print(f"{'':24}{'goal reached':>14}{'wall':>9}")
    print(f"{'network program':24}{net['program_success_rate']:>13.0%}{t_net:>8.0f}s")
    print(f"{'single program':24}{single['program_success_rate']:>13.0%}{t_single:>8.0f}s")
    print(f"{'open-loop replay':24}{single['openloop_success_rate']:>13.0%}{'  same runs':>9}")
    rates = f"{net['program_success_rate']:.2f} / {single['program_success_rate']:.2f}"
    print(f"network / single program: {rates} (target: network >= 0.95 and >= single)")


if __name__ == "__main__":
    main()
