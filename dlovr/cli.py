"""Command-line interface: ``dlovr …`` (click).

Each command validates its input and reports a problem as one line naming the file and the problem,
with exit code 2 and no traceback.
"""

from __future__ import annotations

import click

from dlovr import __version__
from dlovr.batch import cluster_option
from dlovr.cli_common import (
    UserError,
    _one_line,
    _os_errors,
    _plural,
    _scene,
    _warm_up,
)


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
# dlovr scenes, dlovr scene show, dlovr compile, dlovr scene export
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
# dlovr serve
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
    _warm_up()
    from dlovr.ui import serve

    try:
        serve(str(scene.path), host=host, port=port, recordings_dir=recordings_dir)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None
    except OSError as e:
        raise UserError(f"cannot serve on {host}:{port}: {e.strerror or e}") from None


# Commands kept in modules of their own, so that this one stays small
from dlovr.cli_network import network_cmd  # noqa: E402
from dlovr.cli_record import demo_cmd, record_cmd, recover_cmd, replay_cmd, states_cmd  # noqa: E402
from dlovr.execution.cli import run_cmd  # noqa: E402

for _cmd in (demo_cmd, record_cmd, replay_cmd, states_cmd, recover_cmd, network_cmd, run_cmd):
    main.add_command(_cmd)
