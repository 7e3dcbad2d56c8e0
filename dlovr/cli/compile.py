"""``dlovr compile``: recordings into macro programs, or a network into a network program (registered
on the main group by :mod:`dlovr.cli`)."""

from __future__ import annotations

from typing import Any

import click

from dlovr.batch import cluster_option
from dlovr.cli.common import EXIT_BAD_INPUT, UserError, finishes_on_sigterm, os_errors_as_user_errors, plural


@click.command("compile", short_help="Compile recordings (or a network) into macro programs.")
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
@click.option(
    "--force",
    is_flag=True,
    help="Recompile unchanged recordings too, and overwrite programs compile did not write there; "
    "with --network, overwrite -o FILE.",
)
@click.option(
    "--network",
    "network_path",
    type=click.Path(dir_okay=False),
    help="Compile this transition network (from `dlovr network`) into a network program (-o FILE).",
)
@click.option(
    "--sensor-noise",
    type=click.FloatRange(0.0, 1.0),
    help="White noise (N) of the robot's force sensor: detection thresholds respect it.",
)
@click.option(
    "--calibrate",
    is_flag=True,
    help="Calibrate the detectors the demonstration leaves without force signal by running the "
    "program in its scene with a few cables changed (minutes a recording; docs/programs.md).",
)
@cluster_option
@finishes_on_sigterm
@os_errors_as_user_errors
def compile_cmd(
    inputs: tuple[str, ...],
    output_dir: str | None,
    workers: int | None,
    force: bool,
    network_path: str | None,
    cluster: str | None,
    sensor_noise: float | None = None,
    calibrate: bool = False,
) -> None:
    """Compile recordings (files or directories of *.mcap) into macro programs (JSON + text listing),
    or with --network NET.json a transition network into a network program.

    A recording NAME.mcap gives NAME.program.json and NAME.program.txt, beside it or in -o DIR. With
    --sensor-noise N each detection is set for a force sensor with N newtons of white noise: its own
    smoothing and a threshold of at least 4 standard deviations of what it measures; a transition
    whose step is too small for that ends its macro by motion (docs/programs.md, "The sensor"). Two
    recordings with the same name into one -o folder are refused (the message names both). Recordings
    unchanged since they were last compiled there (with the same --sensor-noise) are skipped. An
    existing program is replaced only when compile wrote it there (unchanged since) or with --force:
    a program edited by hand is kept and its recording fails (one line). A recording that cannot be read is
    named and the others are compiled. With --calibrate, each macro whose demonstration shows no force
    signal for its transition is run in the demonstration's scene with the cable as demonstrated, 5 %
    shorter and longer, 0.7x and 1.4x as stiff, ended by the contact tracker, and its detection is
    derived from the wrench sensed there where that gives a usable signal (the program says per
    parameter and per macro; docs/programs.md, "Calibrated detection"). Exit status: 0 all compiled
    or skipped; 2 any failed.
    """
    import os
    from pathlib import Path

    from dlovr.batch import Task, run_batch, summarize
    from dlovr.outputs import prepare_output_dir
    from dlovr.recording import (
        CompileResult,
        check_unique_outputs,
        compile_one,
        find_recordings,
        record_compiled,
    )

    if network_path is not None:
        from dlovr.cli.network import compile_network

        compile_network(network_path, inputs, output_dir, force)
        return
    if not inputs:
        raise UserError("give recordings (files or directories of *.mcap), or --network NET.json")
    if output_dir is not None and os.path.isfile(output_dir):
        raise UserError(f"{output_dir}: is a file, not a directory for programs")
    paths = check_unique_outputs(find_recordings(inputs), output_dir)
    if not paths:
        raise UserError(f"no recordings found in {', '.join(inputs)}")
    if output_dir is not None:
        prepare_output_dir(output_dir)
    if cluster is not None:  # workers elsewhere: absolute paths (on storage every node sees)
        paths = [p.resolve() for p in paths]
        output_dir = str(Path(output_dir).resolve()) if output_dir else None
    cal = None
    if calibrate:
        from dlovr.execution.calibration import calibrate_recording

        cal = calibrate_recording
    tasks = [Task(str(p), (str(p), output_dir, force, sensor_noise, cal)) for p in paths]
    done = sorted(
        run_batch(compile_one, tasks, workers=workers, cluster=cluster, label="compiling"),
        key=lambda d: d.index,
    )
    results = [d.value if d.ok else CompileResult(d.key, None, error=d.error) for d in done]
    record_compiled(results, output_dir, sensor_noise, calibrate)
    if _report(results, summarize(done).retried):
        raise SystemExit(EXIT_BAD_INPUT)


def _report(results: list[Any], retried: int) -> int:
    """Print each recording's result and the counts; return how many failed."""
    failed = [r for r in results if r.error]
    for r in results:
        if r.error:
            click.echo(f"FAILED {r.error}", err=True)
        else:
            note = " (unchanged, skipped)" if r.skipped else ""
            click.echo(f"{r.path} -> {r.json_path}: {plural(r.macros, 'macro')}, {r.risky} risky{note}")
            if r.warning:
                click.echo(f"warning: {r.warning}", err=True)
    skipped = sum(1 for r in results if r.skipped and not r.error)
    compiled = len(results) - len(failed) - skipped
    counts = [f"{compiled} compiled"] + ([f"{skipped} skipped (unchanged)"] if skipped else [])
    click.echo(", ".join([*counts, f"{len(failed)} failed", f"{retried} retried"]))
    return len(failed)
