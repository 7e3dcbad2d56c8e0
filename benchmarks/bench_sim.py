"""Cost of the per-step pipeline on top of bare MuJoCo stepping, on peg-in-hole and on contact-rich
scenes, and how it grows with the number of segments and contacts.

Run: ``.venv/bin/python benchmarks/bench_sim.py [--case peg_in_hole channel drape] [--segments 40]
[--repeat 5] [--clock cpu|wall]``, or ``... --scaling [--plot docs/img/step_cost.png]``

The cases (``--case``): ``peg_in_hole`` (the built-in demonstration, ``scenes/peg_in_hole.script.toml``)
and two contact-rich scenes of ``benchmarks/scenes/``: ``channel`` (a cable lying in a U channel 1 mm
wider than itself, pulled along it and pushed back: every segment touches the floor and both walls,
about three contacts a segment) and ``drape`` (a cable draped across four bars, over their eight top
edges, dragged along them and across them: it crosses edges all the time). Any other name is a
built-in scene with its script.

Each case plays its script along one command stream, three ways, interleaved, ``--repeat`` rounds:

- bare: ``mj_step`` only (the gripper's mocap pose is set untimed);
- sim: ``Simulator.step`` without tracking: gripper motion, divergence checks, the per-step record
  with the raw contact arrays and gripper force;
- sim+extract: ``Simulator(track=True).step``: the above plus contact-state extraction (topology,
  discrete states, forces, debouncing) every step: the per-step pipeline.

Prints µs per step (the median of the rounds; before each row, the chunks' floors: the sum over
chunks of 50 steps of each chunk's least time in any round, which another process's bursts on a shared
machine inflate less than a round's total), the ratio of sim+extract to bare (median, with the
lowest and highest round's: targets at most 1.2 on peg-in-hole at 40 segments, 1.3 on the
contact-rich cases), the real-time factor of sim+extract (2 ms step / time per step), the mean number
of raw contacts per step and how often the tracker labelled all queried points or some of them.

``--scaling`` runs every case at 10, 20, 40, 80, 120 and 200 segments (``--segments`` to change;
``--repeat`` defaults to 1 there) and prints the same table; ``--plot FILE`` draws µs per step
against segments and against contacts per step (matplotlib); ``--from LOG...`` draws it from tables
this script printed before (measuring nothing), so a long run can be done in parts.

``--parts`` then plays each case once more with the pipeline's parts timed inside the running loop
(``mj_step``, the record, the tracker's kernel call, situation, discrete situation, forces and
debouncer, and the garbage collector's pauses), in µs per step.

``--tracker-alone`` then times the contact tracker alone, per case: the records of one untracked
pass fed to fresh trackers (``ContactTracker`` as ``Simulator.step`` calls it), ``--repeat`` rounds,
thread CPU, the collector frozen; in µs per step, median and range. Without ``mj_step`` between its
steps it measures the tracker's own work with far less spread than the ratios (a change of 10 µs
shows there), though not the caches that ``mj_step`` leaves it in the loop.

``--gc freeze`` freezes the objects made before each round (``gc.freeze``, as the commands do after
their setup: ``dlovr.cli.common.freeze_setup``); ``--gc both`` plays each round's sim+extract once
more frozen and prints its ratios beside the default's after the table; with either, ``--parts``
runs frozen.

``--clock cpu`` (the default) times with this thread's CPU time, ``wall`` with the wall clock: on a
shared machine the CPU time leaves out the time other processes hold the cores, which the wall clock
charges to whichever variant ran then.
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import dataclass, replace
from pathlib import Path

import mujoco

from dlovr.scene import load_scene, scenes_dir
from dlovr.script import load_script
from dlovr.sim import DEFAULT_MAX_STRETCH, SimulationDiverged, Simulator

BENCH_SCENES = Path(__file__).resolve().parent / "scenes"
CASES = ("peg_in_hole", "channel", "drape")
TARGETS = {"peg_in_hole": 1.2, "channel": 1.3, "drape": 1.3}
CLOCK = time.thread_time


def script_path(case: str) -> Path:
    """The case's script: a contact-rich scene of benchmarks/scenes/, else a built-in scene's."""
    own = BENCH_SCENES / f"{case}.script.toml"
    return own if own.is_file() else scenes_dir() / f"{case}.script.toml"


def case_scene(case: str, segments: int | None):
    """The case's scene and script, the cable cut into ``segments`` (None: the scene's own)."""
    script = load_script(script_path(case))
    scene = load_scene(script.scene or case)
    if segments is not None:
        scene = replace(scene, dlo=replace(scene.dlo, segments=segments))
    return scene, script


def _commands(scene, script, max_stretch):
    sim = Simulator(scene, max_stretch=max_stretch)
    out, contacts = [], 0
    for rec in sim.run(script):
        out.append((rec.target_pos, rec.target_quat))
        contacts += len(rec.contact_arrays)
    return out, contacts / max(len(out), 1)


def bare(scene, targets, max_stretch, chunks: list[float] | None = None) -> float:
    """Seconds per ``mj_step`` along ``targets``; ``chunks`` gets the seconds of each :data:`CHUNK`
    steps."""
    sim = Simulator(scene, max_stretch=max_stretch)
    m, d = sim.model, sim.data
    clock, cost = CLOCK, _clock_cost()
    total = part = 0.0
    for k, (pos, quat) in enumerate(targets, 1):
        sim.target_pos, sim.target_quat = pos, quat
        sim._move_mocap()
        t0 = clock()
        mujoco.mj_step(m, d)
        part += clock() - t0 - cost
        if chunks is not None and k % CHUNK == 0:
            chunks.append(part)
            total, part = total + part, 0.0
    return (total + part) / len(targets)


_CLOCK_COST: dict[object, float] = {}


def _clock_cost() -> float:
    """About one clock read (s): what an interval between two reads carries besides the work, taken
    off bare's per-step times (an iteration below makes two reads)."""
    if CLOCK not in _CLOCK_COST:
        n = 20000
        t0 = CLOCK()
        for _ in range(n):
            a = CLOCK()
            CLOCK() - a
        _CLOCK_COST[CLOCK] = (CLOCK() - t0) / n / 2.0
    return _CLOCK_COST[CLOCK]


def stepped(
    scene, targets, max_stretch, track: bool, chunks: list[float] | None = None
) -> tuple[float, Simulator]:
    """Seconds per ``Simulator.step`` along ``targets``; ``chunks`` gets the seconds of each
    :data:`CHUNK` steps."""
    sim = Simulator(scene, max_stretch=max_stretch, track=track)
    clock = CLOCK
    t0 = t1 = clock()
    for k, (pos, quat) in enumerate(targets, 1):
        sim.target_pos, sim.target_quat = pos, quat
        sim.step()
        if chunks is not None and k % CHUNK == 0:
            t2 = clock()
            chunks.append(t2 - t1)
            t1 = t2
    return (clock() - t0) / len(targets), sim


#: Steps per chunk of the floor estimate (:func:`floors`).
CHUNK = 50


def floors(rounds: list[list[float]]) -> float:
    """The sum over chunks of each chunk's least seconds in any round, per step: the same steps in
    every round, so another process's burst on the shared cores inflates a chunk in one round and not
    its minimum (an estimate of the quiet machine's cost, beside the medians)."""
    return sum(min(c) for c in zip(*rounds, strict=True)) / (CHUNK * len(rounds[0]))


@dataclass(frozen=True)
class Row:
    """One case at one segment count: medians (s per step) and the rounds' ratios."""

    case: str
    segments: int
    steps: int
    contacts: float
    bare: float
    sim: float
    full: float
    ratios: tuple[float, ...]
    labelled: str

    @property
    def ratio(self) -> float:
        return statistics.median(self.ratios)


def measure(case: str, segments: int | None, repeat: int, max_stretch: float, gc_mode: str = "default",
            frozen: list[float] | None = None) -> Row:
    """Interleaved rounds of bare, sim and sim+extract along the case's commands. ``gc_mode``
    ``freeze``: every round with the objects made before it frozen (``gc.freeze``, as the commands
    do after their setup); ``both``: as by default, and each round's sim+extract once more frozen,
    its ratio to the round's bare ``mj_step`` appended to ``frozen``."""
    import gc

    scene, script = case_scene(case, segments)
    targets, contacts = _commands(scene, script, max_stretch)
    b, s, f = [], [], []
    cb, cs, cf = [], [], []  # per round, the chunks' seconds
    sim = None
    for _ in range(repeat):
        if gc_mode == "freeze":
            gc.freeze()
        cb.append([]), cs.append([]), cf.append([])
        b.append(bare(scene, targets, max_stretch, cb[-1]))
        s.append(stepped(scene, targets, max_stretch, False, cs[-1])[0])
        t, sim = stepped(scene, targets, max_stretch, True, cf[-1])
        f.append(t)
        if gc_mode == "both" and frozen is not None:
            gc.freeze()
            frozen.append(stepped(scene, targets, max_stretch, True)[0] / b[-1])
        gc.unfreeze()
    assert sim is not None
    n, tr = len(targets), sim.tracker
    lab = f"{tr.labellings / n:.1%} / {tr.partial_labellings / n:.1%}"
    med = statistics.median
    fb, fs, ff = floors(cb), floors(cs), floors(cf)
    print(f"  {case}: the chunks' floors ({CHUNK} steps, least of {repeat} rounds each): bare "
          f"{fb * 1e6:.1f}, sim {fs * 1e6:.1f}, sim+extract {ff * 1e6:.1f} µs per step, ratio {ff / fb:.2f}",
          flush=True)
    return Row(case, scene.dlo.segments, n, contacts, med(b), med(s), med(f),
               tuple(x / y for x, y in zip(f, b, strict=True)), lab)


HEAD = ("case", "segments", "steps", "contacts", "bare µs", "sim µs", "sim+extract µs", "ratio",
        "(low-high)", "RTF", "labelled all/some")
FMT = "{:>12} {:>8} {:>6} {:>8} {:>8} {:>8} {:>15} {:>6} {:>12} {:>6} {:>18}"


def print_row(row: Row) -> None:
    spread = f"{min(row.ratios):.2f}-{max(row.ratios):.2f}"
    print(FMT.format(row.case, row.segments, row.steps, f"{row.contacts:.1f}", f"{row.bare * 1e6:.1f}",
                     f"{row.sim * 1e6:.1f}", f"{row.full * 1e6:.1f}", f"{row.ratio:.2f}", spread,
                     f"{0.002 / row.full:.2f}", row.labelled), flush=True)


def plot(rows: list[Row], path: Path) -> None:
    """µs per step (bare and pipeline) against segments, and the pipeline's ratio against contacts."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for case in dict.fromkeys(r.case for r in rows):
        rs = sorted((r for r in rows if r.case == case), key=lambda r: r.segments)
        seg = [r.segments for r in rs]
        (line,) = ax1.plot(seg, [r.full * 1e6 for r in rs], "o-", label=f"{case}: pipeline")
        ax1.plot(seg, [r.bare * 1e6 for r in rs], "o--", color=line.get_color(), alpha=0.6,
                 label=f"{case}: bare mj_step")
        ax2.plot([r.contacts for r in rs], [r.ratio for r in rs], "o-", color=line.get_color(), label=case)
    ax1.set(xlabel="segments", ylabel="µs per step (thread CPU)", title="cost per step")
    ax2.set_xscale("log")
    ax2.set(xlabel="raw contacts per step (mean, log scale)", ylabel="pipeline / bare mj_step",
            title="ratio to bare mj_step")
    ax1.legend(fontsize=7)
    ax2.legend(fontsize=7)
    ax1.grid(alpha=0.3)
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"plot: {path}")


def read_rows(paths: list[Path]) -> list[Row]:
    """The rows of tables this script printed (``--from``)."""
    rows = []
    for path in paths:
        for line in path.read_text().splitlines():
            f = line.split()
            if len(f) == 13 and f[1].isdigit() and f[2].isdigit():
                case, seg, steps, contacts, b, s, full, _ratio, spread = f[:9]
                lo, hi = (float(x) for x in spread.split("-"))
                rows.append(Row(case, int(seg), int(steps), float(contacts), float(b) * 1e-6, float(s) * 1e-6,
                                float(full) * 1e-6, (lo, float(_ratio), hi), f[10] + " / " + f[12]))
    return rows


# the parts of a tracked step that --parts times: (owner module or class, attribute, label)
_PARTS = (
    ("dlovr.sim.simulator:Simulator", "_record", "the record (Simulator._record)"),
    ("dlovr.sim.tracker:ContactTracker", "_state", "the tracker in all (ContactTracker._state)"),
    ("dlovr.sim.tracker:ContactTracker", "_label_step", "  its kernel and the Python by it (_label_step)"),
    ("dlovr.sim.tracker:ContactTracker", "classify", "  the situation (classify), of it:"),
    ("dlovr.sim.tracker", "situation_from_points", "    made again (situation_from_points)"),
    ("dlovr.sim.tracker", "_refreshed", "    refreshed (_refreshed)"),
    ("dlovr.model.discrete:Discretizer", "__call__", "  the discrete situation (Discretizer)"),
    ("dlovr.model.discrete:Discretizer", "again", "  its changing contacts only (Discretizer.again)"),
    ("dlovr.sim.tracker:ContactTracker", "_forces", "  the forces made again (_forces)"),
    ("dlovr.model.transitions:Debouncer", "push", "  the debouncer (Debouncer.push)"),
)


def parts(case: str, segments: int | None, max_stretch: float) -> tuple[int, dict[str, float]]:
    """One tracked pass along the case's commands with the parts of :data:`_PARTS`, ``mj_step`` and the
    garbage collector's pauses timed inside the running loop (``perf_counter``: a thread-clock read
    costs about 2 µs here): steps, and µs per step by part (the parts nest as indented)."""
    import gc
    import importlib

    scene, script = case_scene(case, segments)
    targets, _ = _commands(scene, script, max_stretch)
    clock, spent = time.perf_counter_ns, dict.fromkeys(["mj_step", *(p[2] for p in _PARTS), "gc"], 0)
    saved = []

    def timed(f, label):
        def run(*a, **k):
            t0 = clock()
            try:
                return f(*a, **k)
            finally:
                spent[label] += clock() - t0
        return run

    for where, name, label in (("mujoco", "mj_step", "mj_step"), *_PARTS):
        mod, _, cls = where.partition(":")
        owner = getattr(importlib.import_module(mod), cls) if cls else importlib.import_module(mod)
        saved.append((owner, name, getattr(owner, name)))
        setattr(owner, name, timed(getattr(owner, name), label))
    gc_at = [0]

    def on_gc(phase, _info):
        if phase == "start":
            gc_at[0] = clock()
        else:
            spent["gc"] += clock() - gc_at[0]

    gc.callbacks.append(on_gc)
    try:
        sim = Simulator(scene, max_stretch=max_stretch, track=True)
        for pos, quat in targets:
            sim.target_pos, sim.target_quat = pos, quat
            sim.step()
    finally:
        gc.callbacks.remove(on_gc)
        for owner, name, f in saved:
            setattr(owner, name, f)
    return len(targets), {k: v / len(targets) / 1e3 for k, v in spent.items()}


def print_parts(case: str, segments: int | None, max_stretch: float) -> None:
    n, got = parts(case, segments, max_stretch)
    print(f"{case}: µs per step inside the running loop ({n} steps, wall clock, one pass)")
    for label, us in got.items():
        print(f"  {label:<58} {us:8.1f}")


def tracker_alone(case: str, segments: int | None, max_stretch: float, rounds: int) -> list[float]:
    """µs per step of the contact tracker alone over the records of one untracked pass of the case's
    script, per round (a fresh tracker each, thread CPU, ``gc.freeze()`` before each)."""
    import gc

    scene, script = case_scene(case, segments)
    rows = []
    for r in Simulator(scene, max_stretch=max_stretch).run(script):
        poses = tuple(tuple(getattr(r, k).tolist()) for k in ("gripper_pos", "gripper_quat", "gripper_force"))
        rows.append((r, r.step, r.time, r.points, r.contact_arrays.table, r.contact_arrays, poses, True))
    out = []
    for _ in range(rounds + 1):  # the first round warms the kernels and caches, not counted
        tracker = Simulator(scene, max_stretch=max_stretch, track=True).tracker
        assert tracker is not None
        state = tracker._state  # what Simulator.step calls with the record it made
        gc.collect()
        gc.freeze()
        t0 = time.thread_time()
        for row in rows:
            state(*row)
        out.append((time.thread_time() - t0) / len(rows) * 1e6)
        gc.unfreeze()
    return out[1:]


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "bench_sim").splitlines()[0])
    ap.add_argument("--case", nargs="+", default=list(CASES), help=f"default: {' '.join(CASES)}")
    ap.add_argument("--scene", dest="case", nargs="+", help=argparse.SUPPRESS)  # the old name
    ap.add_argument(
        "--max-stretch", type=float, default=DEFAULT_MAX_STRETCH, help="divergence bound on segment stretch"
    )
    ap.add_argument("--segments", type=int, nargs="+", default=None,
                    help="default: 40 (--scaling: 10 20 40 80 120 200)")
    ap.add_argument("--repeat", type=int, default=None,
                    help="interleaved rounds, the median kept (default 5; --scaling: 1)")
    ap.add_argument("--scaling", action="store_true", help="every case at 10 to 200 segments")
    ap.add_argument("--plot", type=Path, default=None, help="with --scaling: draw the table into FILE")
    ap.add_argument("--clock", choices=("cpu", "wall"), default="cpu", help="thread CPU time or wall clock")
    ap.add_argument("--from", dest="logs", type=Path, nargs="+", default=None,
                    help="with --plot: draw the tables of earlier runs' output instead of measuring")
    ap.add_argument("--gc", choices=("default", "freeze", "both"), default="default",
                    help="freeze: gc.freeze() before each round, as the commands do after their setup; "
                         "both: each round's pipeline also once frozen, printed after the table")
    ap.add_argument("--parts", action="store_true",
                    help="after the table, one pass per case timing the pipeline's parts")
    ap.add_argument("--tracker-alone", action="store_true",
                    help="after the table, the contact tracker alone over recorded steps, per case")
    args = ap.parse_args()
    if args.logs:
        if args.plot is None:
            raise SystemExit("--from needs --plot FILE")
        plot(read_rows(args.logs), args.plot)
        return
    global CLOCK
    CLOCK = time.thread_time if args.clock == "cpu" else time.perf_counter
    segments = args.segments or ([10, 20, 40, 80, 120, 200] if args.scaling else [40])
    repeat = args.repeat or (1 if args.scaling else 5)
    for case in args.case:
        if not script_path(case).is_file():
            raise SystemExit(f"no script for case {case!r} ({script_path(case)})")
    print(f"mujoco {mujoco.__version__}; median of {repeat}; {args.clock} time")
    print(FMT.format(*HEAD))
    rows: list[Row] = []
    lows: list[tuple[Row, list[float]]] = []
    for case in args.case:
        for n in segments:
            frozen: list[float] = []
            try:
                row = measure(case, n, repeat, args.max_stretch, args.gc, frozen)
            except SimulationDiverged as e:
                print(f"{case:>12} {n:>8} diverged: {e}", flush=True)
                continue
            rows.append(row)
            print_row(row)
            if frozen:
                lows.append((row, frozen))
    for row in rows:
        target = TARGETS.get(row.case)
        if target is not None and (row.segments == 40 or not args.scaling):
            met = "met" if row.ratio <= target else "NOT met"
            print(f"{row.case} at {row.segments} segments: median ratio {row.ratio:.2f} "
                  f"(rounds {', '.join(f'{r:.2f}' for r in row.ratios)}), target <= {target}: {met}")
    for row, frozen in lows:
        print(f"{row.case} at {row.segments} segments, sim+extract with gc.freeze() after setup: median "
              f"ratio {statistics.median(frozen):.2f} (rounds {', '.join(f'{x:.2f}' for x in frozen)}) "
              f"against {row.ratio:.2f} without (rounds {', '.join(f'{x:.2f}' for x in row.ratios)})")
    if args.plot is not None and rows:
        plot(rows, args.plot)
    if args.parts:
        if args.gc != "default":  # as the commands run it
            import gc

            gc.freeze()
        for case in args.case:
            print_parts(case, segments[0], args.max_stretch)
    if args.tracker_alone:
        for case in args.case:
            us = tracker_alone(case, segments[0], args.max_stretch, repeat)
            print(f"{case}: the tracker alone, {statistics.median(us):.1f} µs per step (rounds "
                  f"{', '.join(f'{x:.1f}' for x in us)}; thread CPU, records of an untracked pass)")


if __name__ == "__main__":
    main()
