"""``dlovr run``: execute a compiled program in simulation, once or in perturbed trials."""

from __future__ import annotations

import math
import os
import signal
import sys
from dataclasses import dataclass
from typing import Any

import click

from dlovr.batch import cluster_option
from dlovr.cli.common import EXIT_FAILED, EXIT_OK, UserError, freeze_setup, refuse_existing, shown_dir
from dlovr.outputs import rounded


def _number(name: str, raw: str | None, *, integer: bool = False, minimum: float | None = None) -> Any:
    if raw is None:
        return None
    try:
        x = int(raw) if integer else float(raw)
    except ValueError:
        kind = "an integer" if integer else "a number"
        raise UserError(f"{name}: {raw!r} is not {kind}") from None
    if not math.isfinite(x) or (minimum is not None and x < minimum):
        bound = f">= {minimum:g}" if minimum is not None else "finite"
        raise UserError(f"{name}: must be {bound}, got {raw}")
    return x


_PATH_HELP = (
    "Motion of a macro: the demonstration's recorded stretch (demo) or the screw between the program's "
    "poses (program); auto: demo when the recording is found."
)
_VARY_HELP = (
    "Perturb the scene per trial: dlo.length=10%, dlo.young=0.5..2, dlo.friction=30%, "
    "objects.pos=0.005 (metres), objects.yaw=5 (degrees), gripper.pos=0.005 (repeatable; see "
    "dlovr.execution.variation)."
)


@click.command("run", short_help="Execute a program in simulation, or run robustness trials.")
@click.argument("program_path", metavar="PROGRAM.json")
@click.option("--scene", "scene_ref", metavar="NAME|PATH", help="Scene (default: the program's).")
@click.option(
    "--detect",
    metavar="force|oracle",
    default="force",
    show_default=True,
    help="End macros by force detection, or by the contact tracker (oracle).",
)
@click.option("--noise", "noise_raw", metavar="N", help="Force sensor noise, std. dev. in N (default 0).")
@click.option(
    "--sensor-noise",
    "sensor_noise_raw",
    metavar="N",
    help="The sensor noise (N) the detectors are set for (default: --noise).",
)
@click.option(
    "--registered",
    is_flag=True,
    help="Tell the executor where the objects are (each trial's true poses; without --trials, the "
    "scene's against the program's own): macros move in the frame of the objects they touch.",
)
@click.option(
    "--path",
    "path_mode",
    metavar="auto|demo|program",
    default="auto",
    show_default=True,
    help=_PATH_HELP,
)
@click.option("--recording", metavar="FILE", help="The demonstration (default: the program's source).")
@click.option(
    "--network",
    "network_path",
    metavar="NET-PROGRAM.json",
    help="A network program of the scene (dlovr compile --network): where the sensed goal check says "
    "the goal was missed, plan again through it from the sensed situation.",
)
@click.option(
    "--replans",
    "replans_raw",
    metavar="K",
    help="With --network: plan again at most K times (default 2).",
)
@click.option(
    "--frame",
    metavar="world|relative",
    default="world",
    show_default=True,
    help="Frame the demonstrated motion is repeated in.",
)
@click.option("--settle", "settle_raw", metavar="S", help="Hold the start pose S seconds first (default 0).")
@click.option("--allowance", "allowance_raw", metavar="X", help="Motion allowance, x demonstrated (1.5).")
@click.option(
    "--give-way", "give_way_raw", metavar="M",
    help="Slide along a face into a new contact M metres away from it (default: 0.005 following a "
    "hand's demonstration, 0 a script's; docs/programs.md).",
)
@click.option("--trials", "trials_raw", metavar="N", help="Run N perturbed trials (needs -o DIR).")
@click.option("--seed", "seed_raw", metavar="S", default="0", show_default=True, help="Seed of the trials.")
@click.option("--vary", "varies", multiple=True, metavar="KEY=SPEC", help=_VARY_HELP)
@click.option("--baseline", metavar="replay", help="Also replay the demonstration open loop.")
@click.option("--workers", "workers_raw", metavar="K", default="1", show_default=True, help="Processes.")
@click.option(
    "-o",
    "--output",
    "out",
    metavar="DIR|FILE",
    help="With --trials: directory for the trials' results; without: record the run to this MCAP file.",
)
@click.option("--record", is_flag=True, help="With --trials: also record each trial as DIR/trial_KKK.mcap.")
@click.option(
    "-f", "--force", is_flag=True, help="Overwrite the -o run.mcap, or the results in -o DIR, if they exist."
)
@cluster_option
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
def run_cmd(**given: Any) -> None:
    """Execute PROGRAM.json in simulation: each macro a guarded motion ended by the force detector of
    its class (or, with --detect oracle, by the contact tracker), judged against the tracker.

    Prints a table per macro (class, detected at, true transition at, latency, outcome) and the result.
    A network program (from `dlovr compile --network`) runs with sensing and re-planning: after each
    detection the sensed contact vector picks the node reached, and the planner chooses from there; a
    situation outside the network stops the run (dlovr.execution.network_run). A compiled program
    given --network NET-PROGRAM.json recovers through it: where its sensed goal check says the goal
    was missed (after the last macro, or at a macro that failed), it identifies the sensed situation
    in the network, plans again from there and checks the goal again, at most --replans times
    (dlovr.execution.recovery).
    Exit code: 0 the goal was reached, 1 the run failed (a macro's transition never came, the goal
    was not reached, the simulation diverged), 2 bad input.

    With --trials N -o DIR: N runs in scenes perturbed by --vary (deterministic from --seed), with
    --baseline replay also the demonstration replayed open loop; DIR gets trial_KKK.json, trials.csv,
    summary.json and plot.png (results already there are refused unless --force). The trials run on
    --workers local processes, or with --cluster on Ray (local: a Ray instance here; HOST:PORT: a
    running cluster, DIR on storage every node sees), with the same results. Exit code 0 when the
    trials ran (their failures are results), 2 bad input.

    Without --trials, -o run.mcap records the run like a demonstration (an existing file is refused
    unless --force) plus a channel of executor events (/dlovr/executor_events: macro start,
    detection, failure, result), which `dlovr states`, `dlovr replay --verify`, Foxglove and the
    browser timeline open. With --trials, --record also writes each trial's run as
    DIR/trial_KKK.mcap.
    """
    a = RunArgs(**given)
    _check_choices(a)
    n = _numbers(a)
    _check_combinations(a, n)
    from dlovr.model.planning import NetworkProgram, load_runnable

    runnable = load_runnable(a.program_path)  # a ProgramError is an InputError: one line, exit 2
    if isinstance(runnable, NetworkProgram):
        if a.network_path or a.replans_raw:
            raise UserError(f"{a.program_path}: --network and --replans are for a compiled program")
        if a.baseline or a.recording or a.path_mode == "demo":
            why = "a network program has no single demonstration to replay or follow"
            raise UserError(f"{a.program_path}: {why}")
        freeze_setup()
        _network(runnable, a, n)
        return
    program = runnable
    scene, track = _scene_track(program, a)
    opts = _exec_options(a, n)
    recovery = _recovery(program, a)
    use_track = a.path_mode != "program" and track is not None
    import dlovr.execution.run  # noqa: F401  (the simulator and executor, before freeze_setup)

    freeze_setup()
    if n.trials is not None:
        _trials(TrialsArgs(program, scene, track, use_track, opts, bool(a.baseline), recovery), a, n)
        return
    if a.registered:
        opts = _registered(program, scene, opts, a)
    _single(program, scene, opts, track if use_track else None, a, recovery)


def _recovery(program: Any, a: RunArgs) -> Any:
    """The network a compiled program recovers through (``--network``, ``--replans``), or None."""
    if a.replans_raw is not None and not a.network_path:
        raise UserError("--replans needs --network NET-PROGRAM.json")
    if not a.network_path:
        return None
    from dlovr.execution.recovery import MAX_REPLANS, Recovery, check_recovery
    from dlovr.model.planning import NetworkProgram, load_runnable

    replans = _number("--replans", a.replans_raw, integer=True, minimum=0)
    nprog = load_runnable(a.network_path)  # a bad file: one line, exit 2
    if not isinstance(nprog, NetworkProgram):
        why = "not a network program (make one with dlovr compile --network)"
        raise UserError(f"--network {a.network_path}: {why}")
    check_recovery(program, nprog)  # a ProgramError: one line, exit 2
    return Recovery(nprog, MAX_REPLANS if replans is None else replans)


def _registered(program: Any, scene: Any, opts: Any, a: RunArgs) -> Any:
    """``opts`` told where ``scene``'s objects are against the scene the program was made in."""
    from dataclasses import replace

    from dlovr.execution.run import find_recording, resolve_scene
    from dlovr.execution.variation import object_shifts, object_turns

    try:
        nominal = resolve_scene(program, None, find_recording(program, a.recording))
    except ValueError as e:
        raise UserError(f"--registered: {e}") from None
    shifts, turns = object_shifts(nominal, scene), object_turns(nominal, scene)
    return replace(opts, object_shifts=shifts, object_turns=turns)


@dataclass(frozen=True)
class RunArgs:
    """The options of ``dlovr run`` as given (numbers still text: :func:`_numbers` checks them)."""

    program_path: str
    scene_ref: str | None
    detect: str
    noise_raw: str | None
    sensor_noise_raw: str | None
    registered: bool
    path_mode: str
    recording: str | None
    network_path: str | None
    replans_raw: str | None
    frame: str
    settle_raw: str | None
    allowance_raw: str | None
    give_way_raw: str | None
    trials_raw: str | None
    seed_raw: str
    varies: tuple[str, ...]
    baseline: str | None
    workers_raw: str
    out: str | None
    record: bool
    force: bool
    cluster: str | None
    as_json: bool


@dataclass(frozen=True)
class Numbers:
    """The numeric options, checked: noise (N), allowance (x demonstrated), give-way (m; None: by who
    made the demonstration), settle (s), trials, seed, workers."""

    noise: float
    sensor_noise: float | None
    allowance: float
    give_way: float | None
    settle: float
    trials: int | None
    seed: int
    workers: int


@dataclass(frozen=True)
class TrialsArgs:
    """What the trials of a program run: the program, its scene, the demonstration's track (or
    None), whether macros follow it, the executor's options, whether the open-loop replay runs too,
    the network a compiled program recovers through (or None)."""

    program: Any
    scene: Any
    track: Any
    use_track: bool
    opts: Any
    baseline: bool
    recovery: Any = None


def _numbers(a: RunArgs) -> Numbers:
    """The numeric options, each checked (one line naming the option when bad)."""
    return Numbers(
        noise=_number("--noise", a.noise_raw, minimum=0.0) or 0.0,
        sensor_noise=_number("--sensor-noise", a.sensor_noise_raw, minimum=0.0),
        allowance=_number("--allowance", a.allowance_raw, minimum=1.0) or 1.5,
        give_way=_number("--give-way", a.give_way_raw, minimum=0.0),
        settle=_number("--settle", a.settle_raw, minimum=0.0) or 0.0,
        trials=_number("--trials", a.trials_raw, integer=True, minimum=1),
        seed=_number("--seed", a.seed_raw, integer=True, minimum=0),
        workers=_number("--workers", a.workers_raw, integer=True, minimum=1),
    )


def _check_choices(a: RunArgs) -> None:
    """The options that take one of a few words."""
    for name, value, allowed in (
        ("--detect", a.detect, ("force", "oracle")),
        ("--path", a.path_mode, ("auto", "demo", "program")),
        ("--frame", a.frame, ("world", "relative")),
        ("--baseline", a.baseline or "replay", ("replay",)),
    ):
        if value not in allowed:
            raise UserError(f"{name}: {value!r} is not one of {', '.join(allowed)}")


def _check_combinations(a: RunArgs, n: Numbers) -> None:
    """Options that need --trials, and the output each mode writes."""
    if n.trials is None and (a.varies or a.baseline):
        raise UserError("--vary and --baseline need --trials N")
    if n.trials is None and a.cluster:
        raise UserError("--cluster is for --trials")
    if n.trials is None and a.record:
        raise UserError("--record is for --trials (a single run is recorded with -o run.mcap)")
    if n.trials is None and a.out and not a.out.endswith(".mcap"):
        raise UserError(f"-o {a.out}: a single run is recorded to an .mcap file (a directory needs --trials)")
    if n.trials is not None and not a.out:
        raise UserError("--trials needs -o DIR for its results")
    if n.trials is None and a.out:
        refuse_existing(a.out, a.force)


def _exec_options(a: RunArgs, n: Numbers) -> Any:
    """The executor's options of a program run."""
    from dlovr.execution.executor import ExecOptions

    try:
        return ExecOptions(
            detect=a.detect, noise=n.noise, allowance=n.allowance, frame=a.frame, start_settle=n.settle,
            sensor_noise=n.sensor_noise, give_way=n.give_way,
        )
    except ValueError as e:  # options the executor refuses
        raise UserError(str(e)) from None


def _scene_track(program: Any, a: RunArgs) -> tuple[Any, Any]:
    """The scene ``program`` runs in and its demonstration's track (None when not needed, or not
    found and not required)."""
    from dlovr.execution.demo_track import load_track
    from dlovr.execution.run import POSES_INSTEAD, find_recording, not_found, resolve_scene

    try:
        rec_path = find_recording(program, a.recording)
        if a.recording is not None and (rec_path is None or not rec_path.is_file()):
            raise UserError(f"{a.recording}: no such recording")
        scene = resolve_scene(program, a.scene_ref, rec_path)
        track = None
        if a.path_mode in ("auto", "demo") or a.baseline:
            if rec_path is None:
                if a.path_mode == "demo" or a.baseline:
                    why = f"{not_found(program)}: give --recording"
                    raise UserError(f"{a.program_path}: {why}")
                click.echo(  # another way, another result: say so
                    f"note: {a.program_path}: {not_found(program)}, so {POSES_INSTEAD}; give --recording "
                    "FILE to follow the demonstration",
                    err=True,
                )
            else:
                track = load_track(rec_path)
    except ValueError as e:
        raise UserError(str(e)) from None
    return scene, track


def _single(program: Any, scene: Any, opts: Any, track: Any, a: RunArgs, recovery: Any = None) -> None:
    """One run of ``program`` (recorded to ``a.out`` when given, replacing a file there only with
    ``a.force``; recovering through ``recovery``'s network); exit 0 when it reached the goal."""
    import json

    from dlovr.execution.engine import format_result

    out = a.out
    if out:
        from dlovr.execution.recorded import record_run
        from dlovr.outputs import output_error, prepare_output

        try:
            prepare_output(out)
            res = record_run(program, scene, out, opts, track=track, overwrite=a.force, recovery=recovery)
        except OSError as e:
            raise UserError(str(output_error(out, e))) from None
    else:
        from dlovr.execution.run import run_program

        res = run_program(program, scene, opts, track=track, recovery=recovery)
    if a.as_json:
        click.echo(json.dumps(rounded(res.to_json()), indent=1))
    else:
        click.echo(format_result(res))
    sys.exit(EXIT_OK if res.success else EXIT_FAILED)


def _network(nprog: Any, a: RunArgs, n: Numbers) -> None:
    """``dlovr run NETWORK-PROGRAM.json``: one run (optionally recorded), or trials."""
    import json

    from dlovr.execution.engine import format_result
    from dlovr.execution.executor import ExecOptions
    from dlovr.execution.network_run import network_scene
    from dlovr.execution.run import run_program

    try:
        scene = network_scene(nprog, a.scene_ref)
        opts = ExecOptions(
            detect=a.detect, noise=n.noise, allowance=n.allowance, sensor_noise=n.sensor_noise,
            give_way=n.give_way,
        )
    except ValueError as e:  # a ProgramError, a SceneError, or options the executor refuses
        raise UserError(str(e)) from None
    if n.trials is not None:
        _trials(TrialsArgs(nprog, scene, None, False, opts, False), a, n)
        return
    out = a.out
    if out:
        from dlovr.execution.recorded import record_run

        try:
            res = record_run(nprog, scene, out, opts, overwrite=a.force)
        except OSError as e:
            raise UserError(f"{out}: cannot write: {e.strerror}") from None
    else:
        res = run_program(nprog, scene, opts)
    click.echo(json.dumps(rounded(res.to_json()), indent=1) if a.as_json else format_result(res))
    sys.exit(EXIT_OK if res.success else EXIT_FAILED)


def _trials(t: TrialsArgs, a: RunArgs, n: Numbers) -> None:
    """``--trials N -o DIR``: the trials run, their results written, a summary printed."""
    from pathlib import Path

    from dlovr.execution.trials import TrialSetup, run_trials, summarize
    from dlovr.execution.variation import parse_varies
    from dlovr.geometry import scene_pieces
    from dlovr.outputs import check_writable_dir

    out, trials = a.out or "", n.trials or 0  # both given (see _check_combinations)
    variations = parse_varies(a.varies, t.scene)
    if Path(out).exists() and not Path(out).is_dir():
        raise UserError(f"{out}: exists and is not a directory")
    _refuse_results(out, trials, a)
    pieces = scene_pieces(t.scene)
    record_dir = str(Path(out).resolve()) if a.record else None
    setup = TrialSetup(
        program=t.program,
        scene=t.scene,
        pieces=pieces,
        track=t.track,
        variations=variations,
        seed=n.seed,
        opts=t.opts,
        baseline=t.baseline,
        use_track=t.use_track,
        record_dir=record_dir,
        registered=a.registered,
        force=a.force,
        recovery=t.recovery,
    )
    check_writable_dir(out)  # before the batch: a folder that takes no file fails now, not after it
    try:
        results = run_trials(setup, trials, workers=n.workers, cluster=a.cluster, progress=True)
    except (KeyboardInterrupt, SystemExit) as e:
        _interrupted_trials(e, setup, trials, out)
        raise
    summary = summarize(results, setup)
    _write_trials(out, results, summary, a.force)
    _print_summary(summary, trials, out)


def _refuse_results(out: str, trials: int, a: RunArgs) -> None:
    """Before the batch: results already in ``out`` (a trial's JSON or recording, the summary, the
    table, the plot) are one line, exit 2, unless --force."""
    from dlovr.execution.trials import result_names

    if a.force or not os.path.isdir(out):
        return
    there = [name for name in result_names(trials, a.record) if os.path.lexists(os.path.join(out, name))]
    if there:
        raise UserError(f"{os.path.join(out, there[0])}: exists; give --force to overwrite the results")


def _write_trials(out: str, results: list[dict[str, Any]], summary: dict[str, Any], force: bool) -> None:
    """The trials' files (:func:`dlovr.execution.trials.write_outputs`, atomic; existing ones replaced
    only with ``force``); a failed write is one line."""
    from dlovr.execution.trials import write_outputs
    from dlovr.outputs import OutputError, describe_os_error

    try:
        write_outputs(out, results, summary, force=force)
    except OutputError as e:
        raise UserError(f"{e} (the results of {len(results)} trials)") from None
    except OSError as e:
        where = e.filename or out
        why = describe_os_error(e)
        raise UserError(f"{where}: cannot write: {why} (the results of {len(results)} trials)") from None


def _interrupted_trials(e: BaseException, setup: Any, n: int, out: str) -> None:
    """A signal ended the trials: write the finished ones' results (as after a whole batch) and say
    so in one line, exit 130 or 143. (Another ``SystemExit`` returns: the caller re-raises it.)"""
    from dlovr import signals
    from dlovr.batch import finished
    from dlovr.execution.trials import lost_trial, summarize

    if isinstance(e, SystemExit) and not isinstance(e, signals.SignalExit) and signals.pending() is None:
        return
    done = sorted(finished(e), key=lambda r: r.index)
    results = [{**(r.value if r.ok else lost_trial(setup, r.index, str(r.error))), "attempts": r.attempts}
               for r in done]
    if results:
        _write_trials(out, results, summarize(results, setup), setup.force)
    signum = signals.pending() or (signal.SIGINT if isinstance(e, KeyboardInterrupt) else signal.SIGTERM)
    where = f"their results in {shown_dir(out)}" if results else "no results written"
    name = signals.name(signum)
    click.echo(f"\ninterrupted ({name}): {len(results)} of {n} trials finished, {where}", err=True)
    signals.clear()
    raise SystemExit(signals.exit_code(signum))


def _print_summary(summary: dict[str, Any], trials: int, out: str) -> None:
    """The trials' summary in a few lines."""
    rate = summary["program_success_rate"]
    line = f"program reached the goal in {rate:.0%} of {trials} trials"
    if summary["openloop_success_rate"] is not None:
        line += f", open-loop replay in {summary['openloop_success_rate']:.0%}"
    lat = summary["median_latency_s"]
    line += f"; median detection latency {lat * 1000:.0f} ms" if lat is not None else "; no detection latency"
    fr = summary["false_detection_rate"]
    if fr is not None:
        line += f"; false detections {summary['false_detections']} of {summary['macros_run']} macros"
        line += f" ({fr:.1%})"
    if summary.get("went_on"):
        line += f"; {summary['went_on']} macros not felt went on (a hand's program)"
    click.echo(line)
    rp = summary.get("replans") or {}
    if rp.get("replanned"):
        click.echo(f"planned again through the network in {rp['replanned']} trials, "
                   f"{rp['recovered']} of them reached the goal")
    if summary["retried_trials"] or summary["lost_trials"]:
        lost = f"{summary['retried_trials']} trials retried (a worker died), {summary['lost_trials']} lost"
        click.echo(lost)
    click.echo(f"results in {shown_dir(out)} (summary.json, trials.csv, plot.png, trial_*.json)")
