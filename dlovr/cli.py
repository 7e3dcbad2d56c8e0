"""Command-line interface: ``dlovr …`` (click).

Each command validates its input and reports a problem as one line naming the file and the problem,
with exit code 2 and no traceback.
"""

from __future__ import annotations

import click

from dlovr import __version__
from dlovr.batch import cluster_option


class UserError(click.ClickException):
    """A problem with the user's input: printed as one line, exit code 2."""

    exit_code = 2


def _plural(n: int, word: str) -> str:
    """``1 macro``, ``2 macros``."""
    return f"{n} {word}{'' if n == 1 else 's'}"


def _t(seconds: float) -> float:
    """A time (s) as printed and exported: rounded to the microsecond (a plain float, no numpy type);
    recordings keep the exact values."""
    return round(float(seconds), 6)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="dlovr")
def main() -> None:
    """dlovr: demonstrate DLO (cable) manipulation, extract contact states, compile programs."""


# --------------------------------------------------------------------------------------------------
# dlovr transitions
# --------------------------------------------------------------------------------------------------


def _load_facts(path: str):
    from dlovr.facts import FactsError, load_facts

    try:
        return load_facts(path)
    except FactsError as e:
        raise UserError(str(e)) from None


@main.command("transitions", short_help="Classify a hand-written sequence of situations.")
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@click.option("--unicode/--ascii", default=False, help="Notation in the table (default ASCII).")
@click.option(
    "--facts",
    type=click.Path(dir_okay=False),
    help="JSON with face normals, face-pair relations and DLO vectors, needed for topological lines.",
)
@click.option("--hold", type=click.FloatRange(min=0.0), help="Timed input: hold time, s (default 0.01).")
@click.option("--flight", type=click.FloatRange(min=0.0), help="Timed input: flight time, s (default 0.3).")
def transitions_cmd(
    file: str, as_json: bool, unicode: bool, facts: str | None, hold: float | None, flight: float | None
) -> None:
    """Classify the transitions of a sequence of situations, one per line of FILE.

    Lines hold discrete situations (``V/G & E/N & V/F[box.F1]``) or topological ones
    (``VS/G & E3/N & VE/box.F1``, which need --facts); ``#`` starts a comment. A line may start with
    a time in seconds (``0.012  V/G & E/N & V/N``): then every line must, and the sequence is
    debounced as a simulation's is (flicker within --hold, brief intermediate states, flights within
    --flight) before it is classified; each row shows when its kept situation began.
    """
    import json

    from dlovr.model.sequence import SequenceError, debounce_sequence, parse_sequence
    from dlovr.model.transitions import DEFAULT_FLIGHT_S, DEFAULT_HOLD_S, classify_sequence, format_classes

    try:
        with open(file, encoding="utf-8") as fh:
            lines = fh.read().splitlines()
    except OSError as e:
        raise UserError(f"{file}: cannot read: {e.strerror}") from None
    except UnicodeDecodeError:
        raise UserError(f"{file}: not a UTF-8 text file") from None
    book, vectors = _load_facts(facts) if facts else (None, None)
    try:
        rows = parse_sequence(lines, book, vectors)  # type: ignore[arg-type]
    except SequenceError as e:
        raise UserError(f"{file}:{e.line}: {e}" if e.line else f"{file}: {e}") from None
    if rows[0].t is None:
        if hold is not None or flight is not None:
            raise UserError(f"{file}: --hold and --flight debounce timed input; no line starts with a time")
        steps = classify_sequence([r.discrete for r in rows])
        if as_json:
            out = [
                {
                    "step": s.index + 1,
                    "line": r.line,
                    "topological": r.topological.format() if r.topological is not None else None,
                    "discrete": s.situation.format(),
                    "classes": list(s.classes),
                    "label": s.label,
                }
                for s, r in zip(steps, rows, strict=True)
            ]
            click.echo(json.dumps(out, indent=2, ensure_ascii=False))
            return
        click.echo(f"{'step':>4}  {'class':<5}  situation")
        for s in steps:
            click.echo(f"{s.index + 1:>4}  {s.label:<5}  {s.situation.format(unicode)}")
        return
    kept = debounce_sequence(
        rows, DEFAULT_HOLD_S if hold is None else hold, DEFAULT_FLIGHT_S if flight is None else flight
    )
    if as_json:
        out = [
            {
                "step": i,
                "line": k.line.line,
                "t": k.kept.start,
                "duration": round(k.kept.duration, 9),
                "through_free": k.kept.through_free,
                "topological": k.line.topological.format() if k.line.topological is not None else None,
                "discrete": k.kept.situation.format(),
                "classes": list(k.classes),
                "label": format_classes(k.classes),
            }
            for i, k in enumerate(kept, 1)
        ]
        click.echo(json.dumps(out, indent=2, ensure_ascii=False))
        return
    click.echo(f"{'step':>4}  {'t [s]':>9}  {'class':<5}  situation")
    for i, k in enumerate(kept, 1):
        label, sit = format_classes(k.classes), k.kept.situation.format(unicode)
        click.echo(f"{i:>4}  {k.kept.start:9.3f}  {label:<5}  {sit}")


# --------------------------------------------------------------------------------------------------
# Simulation, recording, replay, programs
# --------------------------------------------------------------------------------------------------


def _scene(ref: str, script=None):
    """Load a scene; one that a script names is reported with the script's file."""
    from dlovr.scene import SceneError, load_scene

    try:
        return load_scene(ref)
    except SceneError as e:
        raise UserError(f"{script.source}: scene: {e}" if script is not None else str(e)) from None


def _script(path: str):
    from dlovr.script import ScriptError, load_script

    try:
        return load_script(path)
    except ScriptError as e:
        raise UserError(str(e)) from None


def _builtin_script(scene_name: str) -> str:
    from dlovr.scene import scenes_dir

    p = scenes_dir() / f"{scene_name}.script.toml"
    if not p.is_file():
        raise UserError(
            f"scene {scene_name} has no built-in demonstration script ({p.name}); give --script FILE"
        )
    return str(p)


def _progress(total: int, label: str):
    import sys

    return click.progressbar(length=total, label=label, file=sys.stderr, show_eta=True, show_percent=True)


def _one_line(fn):
    """Report a bad recording or an output path that cannot be written as one line (exit 2). SIGTERM
    ends the command as an exception (exit 143), so that its temporary files and folders are removed."""
    import functools

    from dlovr.outputs import OutputError
    from dlovr.recording import RecordingError, finish_on_sigterm

    @functools.wraps(fn)
    def wrapper(*a, **kw):
        try:
            with finish_on_sigterm():
                return fn(*a, **kw)
        except (RecordingError, OutputError) as e:
            raise UserError(str(e)) from None

    return wrapper


def _os_errors(fn):
    """Report an ``OSError`` while writing outputs as one line naming the file (exit 2)."""
    import functools

    from dlovr.outputs import describe_os_error

    @functools.wraps(fn)
    def wrapper(*a, **kw):
        try:
            return fn(*a, **kw)
        except OSError as e:
            raise UserError(f"{e.filename or 'output'}: cannot write: {describe_os_error(e)}") from None

    return wrapper


def run_demonstration(scene_ref: str | None, script_path: str | None, out: str | None, label: str):
    """Run a scripted demonstration headless (optionally recording it); return (scene, tracker).

    Without a script, the scene's built-in one; without a scene, the script's (a path in a script is
    relative to the script's folder), else ``table``. ``out``'s parent directories are created; when
    it cannot be written, the partial file is removed and the run stops with one line.
    """
    import os
    from contextlib import nullcontext

    from dlovr.outputs import output_error, prepare_output, remove_partial
    from dlovr.recording import DemoRecorder, StopSignals, finish_on_sigterm
    from dlovr.sim import SimulationDiverged, Simulator

    if script_path is None:
        if scene_ref is None:
            raise UserError("give --scene NAME|PATH or --script FILE")
        scene = _scene(scene_ref)
        script = _script(_builtin_script(scene_ref))
    else:
        script = _script(script_path)
        if scene_ref is not None:
            scene = _scene(scene_ref)
        else:
            scene = _scene(script.scene, script) if script.scene else _scene("table")
    try:
        sim = Simulator(scene, track=True)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None
    tracker = sim.tracker
    nsteps = round(script.total_duration / sim.model.opt.timestep)
    existed = out is not None and os.path.lexists(out)
    if out is not None:
        prepare_output(out)
    stop = StopSignals() if out else None  # while recording, a signal ends it between two steps
    try:
        with finish_on_sigterm(), stop or nullcontext():
            recorder = DemoRecorder(out, scene, sim, tracker) if out else nullcontext()
            with recorder as rec, _progress(nsteps, label) as bar:
                try:
                    for k, record in enumerate(sim.run(script), 1):
                        if rec is not None:
                            rec.step(record)
                        if k % 100 == 0:
                            bar.update(100)
                        if stop is not None and stop.signum is not None:
                            break
                except SimulationDiverged as e:
                    if rec is not None:  # the end marker says so; compile warns
                        rec.end_reason = str(e)
                    saved = f"; the recording up to there is kept: {out}" if out else ""
                    raise click.ClickException(f"{e}{saved}") from None
    except OSError as e:
        if out is None:
            raise
        removed = not existed and remove_partial(out)
        raise UserError(str(output_error(out, e)) + (" (partial file removed)" if removed else "")) from None
    if stop is not None and stop.signum is not None:
        kept = f"recording kept: {out}, {rec.duration:.3f} s of simulated time"
        click.echo(f"interrupted ({stop.name}): {kept}", err=True)
        raise SystemExit(stop.exit_code)
    return scene, tracker


def _states_table(rows: list[dict]) -> str:
    lines = [f"{'step':>4}  {'t [s]':>8}  {'class':<5}  topological  |  discrete"]
    for i, r in enumerate(rows, 1):
        cls = ",".join(r["classes"]) or "-"
        lines.append(f"{i:>4}  {r['t']:8.3f}  {cls:<5}  {r['topological']}  |  {r['discrete']}")
    return "\n".join(lines)


def _kept_rows(tracker) -> list[dict]:
    """Fig. 11 style rows from a tracker: kept situations with their topological form and classes."""
    by_start = {}
    for st in tracker.changes:
        by_start.setdefault((st.t, st.discrete), st)
    rows = []
    for kept, classes in tracker.transitions():
        st = by_start.get((kept.start, kept.situation))
        rows.append(
            {
                "t": _t(kept.start),
                "duration": _t(kept.duration),
                "topological": st.topological.format() if st else "",
                "discrete": kept.situation.format(),
                "classes": list(classes),
            }
        )
    return rows


@main.command("demo", short_help="Run a built-in demonstration headless, print its states.")
@click.option(
    "--scene",
    "scene_ref",
    help="Built-in scene name or path (default: the script's scene, else peg_in_hole).",
)
@click.option("--script", "script_path", type=click.Path(dir_okay=False), help="Demonstration script (TOML).")
@click.option(
    "-o", "--record", "out", type=click.Path(dir_okay=False), help="Also record it to this MCAP file."
)
@click.option("--json", "as_json", is_flag=True, help="Print the situations as JSON.")
@_one_line
def demo_cmd(scene_ref: str, script_path: str | None, out: str | None, as_json: bool) -> None:
    """Run a built-in demonstration headless and print its contact situations (Fig. 11 style)."""
    import json

    if scene_ref is None and script_path is None:
        scene_ref = "peg_in_hole"
    _, tracker = run_demonstration(scene_ref, script_path, out, f"demo {scene_ref or script_path}")
    rows = _kept_rows(tracker)
    click.echo(json.dumps(rows, indent=2) if as_json else _states_table(rows))


@main.command("record", short_help="Record a scripted demonstration to an MCAP file.")
@click.option("--scene", "scene_ref", help="Built-in scene name or path (default: the script's scene).")
@click.option(
    "--script", "script_path", required=True, type=click.Path(dir_okay=False), help="Script (TOML)."
)
@click.option(
    "-o", "--output", "out", required=True, type=click.Path(dir_okay=False), help="Output MCAP file."
)
@click.option("--force", is_flag=True, help="Overwrite the output file if it exists.")
@_one_line
def record_cmd(scene_ref: str | None, script_path: str, out: str, force: bool) -> None:
    """Record a scripted demonstration headless to an MCAP file.

    An existing output file is refused unless --force. Ctrl-C or SIGTERM end the recording between
    two steps: the file is kept, finished, and replays and verifies (`dlovr replay --verify`).

    Exit status: 0 done; 2 bad input; 1 the simulation diverged (the recording is kept up to there);
    130 (Ctrl-C, SIGINT) or 143 (SIGTERM) interrupted, the recording so far kept.
    """
    _refuse_existing(out, force)
    _, tracker = run_demonstration(scene_ref, script_path, out, "recording")
    click.echo(f"wrote {out}: {_plural(len(tracker.kept), 'contact situation')}")


def _refuse_existing(out: str, force: bool) -> None:
    """One line, exit 2, if ``out`` exists and may not be overwritten."""
    import os

    if os.path.lexists(out) and not force:
        raise UserError(f"{out}: exists; give --force to overwrite it")


@main.command("replay", short_help="Re-simulate a recording, or verify it bit for bit.")
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("--verify", is_flag=True, help="Compare every checkpoint bit for bit and the contact states.")
@_one_line
def replay_cmd(recording: str, verify: bool) -> None:
    """Re-simulate a recording from its embedded scene and command stream.

    Exit status: 0 replayed (with --verify: bit-identical); 1 with --verify: the replay diverged from
    the recording; 2 the recording cannot be read (damaged, not a recording, ...).
    """
    from dlovr.recording import replay

    with _progress(1, "replay") as bar:
        done = [0]

        def progress(k: int, total: int) -> None:
            bar.length = total
            bar.update(k - done[0])
            done[0] = k

        res = replay(recording, verify=verify, progress=progress)
    for w in res.warnings:
        click.echo(f"warning: {w}", err=True)
    rtf = res.sim_time / res.wall_time if res.wall_time > 0 else float("inf")
    click.echo(
        f"replayed {res.steps} steps ({res.sim_time:.2f} s) in {res.wall_time:.2f} s, {rtf:.1f}x real time"
    )
    if verify:
        if res.divergence:
            raise click.ClickException(f"{recording}: replay diverged: {res.divergence}")
        click.echo("verified: every checkpoint bit-identical, contact states identical")


@main.command("states", short_help="Print a recording's contact situations and transitions.")
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option(
    "--format", "fmt", type=click.Choice(["table", "json", "csv"]), default="table", show_default=True
)
@click.option("--raw", is_flag=True, help="Every recorded change, not debounced.")
@_one_line
def states_cmd(recording: str, fmt: str, raw: bool) -> None:
    """Print a recording's contact situations and transitions (reads only the contact-state channel)."""
    import csv
    import io
    import json

    from dlovr.model.transitions import kept_classes
    from dlovr.recording import Recording, kept_states

    rec = Recording(recording)
    if raw:
        rows = [
            {
                "t": _t(p["t"]),
                "topological": p["topological"],
                "discrete": p["discrete"],
                "classes": p.get("classes", []),
            }
            for p in rec.states()
            if not p.get("end")  # the end marker repeats the last situation
        ]
    else:
        kept = kept_states(rec)
        rows = [
            {
                "t": _t(k.t),
                "duration": _t(k.duration),
                "topological": k.topological or "",
                "discrete": k.situation.format(),
                "classes": list(classes),
            }
            for k, classes in zip(kept, kept_classes(kept), strict=True)
        ]
    if fmt == "json":
        click.echo(json.dumps(rows, indent=2))
    elif fmt == "csv":
        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow(["t", "classes", "topological", "discrete"])
        for r in rows:
            w.writerow([r["t"], ",".join(r["classes"]) or "-", r["topological"], r["discrete"]])
        click.echo(buf.getvalue(), nl=False)
    else:
        click.echo(_states_table(rows))


@main.command("recover", short_help="Rescue a recording whose writer was killed.")
@click.argument("broken", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "out", required=True, type=click.Path(dir_okay=False), help="Recovered file.")
@click.option("--force", is_flag=True, help="Overwrite the output file if it exists.")
@_one_line
def recover_cmd(broken: str, out: str, force: bool) -> None:
    """Rescue every intact part of a damaged recording or of one whose writer was killed.

    Damaged chunks are skipped (and listed with their time ranges), every intact one is kept. A file
    whose writer was killed is cut at its last checkpoint (at most the last 2 s of simulated time are
    lost), so that it replays and verifies. Exit status: 0 written; 2 nothing recoverable or bad input.
    """
    from pathlib import Path

    from dlovr.outputs import atomic_output
    from dlovr.recording import RecordingError, recover

    if Path(broken).resolve() == Path(out).resolve():
        raise RecordingError(f"{out}: recover writes a new file; choose another output path")
    _refuse_existing(out, force)
    with atomic_output(out) as tmp:  # no partial file at ``out`` if writing fails
        rep = recover(broken, tmp)
    click.echo(
        f"wrote {out}: {_plural(rep.messages, 'message')}, {_plural(rep.attachments, 'attachment')}, "
        f"{rep.last_time_s:.2f} s"
    )
    for line in rep.skipped:
        click.echo(f"skipped {line}", err=True)


# --------------------------------------------------------------------------------------------------
# dlovr scenes, dlovr scene show (issue 3)
# --------------------------------------------------------------------------------------------------


@main.command("scenes", short_help="List the built-in scenes.")
def scenes_cmd() -> None:
    """List the built-in scenes (use them by name, e.g. ``dlovr scene show peg_in_hole``)."""
    from dlovr.scene import builtin_scenes

    rows = builtin_scenes()
    width = max((len(n) for n, _ in rows), default=4)
    for name, desc in rows:
        click.echo(f"{name:<{width}}  {desc}")


@main.group("scene", short_help="Inspect scenes: show one, export its MuJoCo model.")
def scene_group() -> None:
    """Inspect scenes: built-in ones by name, others by the path of their TOML file."""


@scene_group.command("show", short_help="Print a scene's objects, pieces, faces and edges.")
@click.argument("ref", metavar="NAME|PATH")
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
def scene_show_cmd(ref: str, as_json: bool) -> None:
    """Print a scene: cable, gripper, objects, convex pieces, named faces and the edge table."""
    import json

    from dlovr.scene import SceneError, describe_scene, format_scene, load_scene

    try:
        desc = describe_scene(load_scene(ref))
    except SceneError as e:
        raise UserError(str(e)) from None
    click.echo(json.dumps(desc, indent=2, ensure_ascii=False) if as_json else format_scene(desc))


@main.command("compile", short_help="Compile recordings (or a network) into macro programs.")
@click.argument("inputs", nargs=-1, type=click.Path())
@click.option(
    "-o",
    "--output-dir",
    type=click.Path(),
    help="Where programs go (default: beside each); with --network, the program file to write.",
)
@click.option(
    "--workers",
    type=click.IntRange(1, 64),
    help="Worker processes (default 1); with --cluster, tasks in flight (default: every CPU).",
)
@click.option("--force", is_flag=True, help="Recompile unchanged recordings too.")
@click.option(
    "--network",
    "network_path",
    type=click.Path(dir_okay=False),
    help="Compile this transition network (from `dlovr network`) into a network program (-o FILE).",
)
@cluster_option
@_one_line
@_os_errors
def compile_cmd(
    inputs: tuple[str, ...],
    output_dir: str | None,
    workers: int | None,
    force: bool,
    network_path: str | None,
    cluster: str | None,
) -> None:
    """Compile recordings (files or directories of *.mcap) into macro programs (JSON + text listing),
    or with --network NET.json a transition network into a network program.

    A recording NAME.mcap gives NAME.program.json and NAME.program.txt, beside it or in -o DIR. Two
    recordings with the same name into one -o folder are refused (the message names both). Recordings
    unchanged since they were last compiled there are skipped. A recording that cannot be read is
    named and the others are compiled. Exit status: 0 all compiled or skipped; 2 any failed.
    """
    import os
    from pathlib import Path

    from dlovr.batch import Task, run_batch, summarize
    from dlovr.outputs import prepare_output_dir
    from dlovr.recording import (
        CompileResult,
        RecordingError,
        check_unique_outputs,
        compile_one,
        find_recordings,
        record_compiled,
    )

    if network_path is not None:
        from dlovr.cli_network import compile_network

        compile_network(network_path, inputs, output_dir)
        return
    if not inputs:
        raise UserError("give recordings (files or directories of *.mcap), or --network NET.json")
    if output_dir is not None and os.path.isfile(output_dir):
        raise UserError(f"{output_dir}: is a file, not a directory for programs")
    try:
        paths = check_unique_outputs(find_recordings(inputs), output_dir)
    except RecordingError as e:
        raise UserError(str(e)) from None
    if not paths:
        raise UserError(f"no recordings found in {', '.join(inputs)}")
    if output_dir is not None:
        prepare_output_dir(output_dir)
    if cluster is not None:  # workers elsewhere: absolute paths (on storage every node sees)
        paths = [p.resolve() for p in paths]
        output_dir = str(Path(output_dir).resolve()) if output_dir else None
    tasks = [Task(str(p), (str(p), output_dir, force)) for p in paths]
    done = sorted(
        run_batch(compile_one, tasks, workers=workers, cluster=cluster, label="compiling"),
        key=lambda d: d.index,
    )
    results = [d.value if d.ok else CompileResult(d.key, None, error=d.error) for d in done]
    record_compiled(results, output_dir)
    failed = [r for r in results if r.error]
    for r in results:
        if r.error:
            click.echo(f"FAILED {r.error}", err=True)
        else:
            note = " (unchanged, skipped)" if r.skipped else ""
            click.echo(f"{r.path} -> {r.json_path}: {_plural(r.macros, 'macro')}, {r.risky} risky{note}")
            if r.warning:
                click.echo(f"warning: {r.warning}", err=True)
    skipped = sum(1 for r in results if r.skipped and not r.error)
    compiled = len(results) - len(failed) - skipped
    counts = [f"{compiled} compiled"] + ([f"{skipped} skipped (unchanged)"] if skipped else [])
    retried = summarize(done).retried
    click.echo(", ".join([*counts, f"{len(failed)} failed", f"{retried} retried"]))
    if failed:
        raise SystemExit(2)


@scene_group.command("export", short_help="Write a scene's compiled MuJoCo model (MJCF).")
@click.argument("ref", metavar="NAME|PATH")
@click.option(
    "-o", "--output", "out", required=True, type=click.Path(dir_okay=False), help="MJCF file to write."
)
@_one_line
def scene_export_cmd(ref: str, out: str) -> None:
    """Write the scene's compiled MuJoCo model (MJCF, meshes inline), loadable by plain MuJoCo."""
    from dlovr.outputs import atomic_output
    from dlovr.sim import Simulator, export_xml

    scene = _scene(ref)
    try:
        sim = Simulator(scene)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None
    with atomic_output(out) as tmp:  # no partial file at ``out`` if writing fails
        export_xml(sim.built, tmp)
    click.echo(f"wrote {out}")


# --------------------------------------------------------------------------------------------------
# dlovr serve (issue 6)
# --------------------------------------------------------------------------------------------------


@main.command("serve", short_help="Serve the browser teleoperation UI.")
@click.option("--scene", "scene_ref", default="table", show_default=True, help="Built-in scene name or path.")
@click.option("--host", default="127.0.0.1", show_default=True, help="Address to listen on.")
@click.option(
    "--port",
    type=click.IntRange(1, 65535),
    default=8080,
    show_default=True,
    help="Port (the next free one if taken).",
)
@click.option(
    "--recordings",
    "recordings_dir",
    default="recordings",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Directory for recordings made in the browser.",
)
def serve_cmd(scene_ref: str, host: str, port: int, recordings_dir: str) -> None:
    """Serve the browser teleoperation UI (viser) with the simulation running in real time."""
    scene = _scene(scene_ref)
    from dlovr.ui import serve

    try:
        serve(str(scene.path), host=host, port=port, recordings_dir=recordings_dir)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None
    except OSError as e:
        raise UserError(f"cannot serve on {host}:{port}: {e.strerror or e}") from None


# dlovr network (issue 19): its own module, so this one stays small
from dlovr.cli_network import network_cmd  # noqa: E402

main.add_command(network_cmd)
