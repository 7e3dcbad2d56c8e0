"""The ``dlovr`` commands that simulate, record and read recordings: ``demo``, ``record``, ``replay``,
``states``, ``recover`` (registered on the main group by :mod:`dlovr.cli`)."""

from __future__ import annotations

import os
from contextlib import nullcontext
from typing import Any

import click

from dlovr.batch import cluster_option
from dlovr.cli.common import (
    EXIT_FAILED,
    UserError,
    builtin_script,
    finishes_on_sigterm,
    freeze_setup,
    load_scene_arg,
    plural,
    progress_bar,
    refuse_existing,
    rounded_time,
    script_scene,
    shown_dir,
    warm_up,
)


def demonstrate(
    scene_ref: str | None, script_path: str | None, out: str | None, label: str, force: bool = False
) -> Any:
    """Run a scripted demonstration headless (optionally recording it to ``out``); return its tracker.

    Without a script, the scene's built-in one; without a scene, the script's (a path in a script is
    relative to the script's folder), else ``table``. ``out``'s parent directories are created; when
    it cannot be written, the partial file is removed and the run stops with one line. An existing
    ``out`` is replaced only with ``force`` (and only once the new one is finished); without it, one
    that another writer created meanwhile is refused, not shared.
    """
    from dlovr.outputs import output_error, prepare_output, remove_partial
    from dlovr.recording import StopSignals, finish_on_sigterm
    from dlovr.recording.scripted import play_script

    scene, script = _scene_and_script(scene_ref, script_path)
    sim = _simulator(scene)
    freeze_setup()
    nsteps = round(script.total_duration / sim.model.opt.timestep)
    existed = out is not None and os.path.lexists(out)
    if out is not None:
        prepare_output(out)
    stop = StopSignals() if out else None  # while recording, a signal ends it between two steps
    rec = None
    try:
        with finish_on_sigterm(), stop or nullcontext():
            rec = _recorder(out, scene, sim, force)
            with rec or nullcontext(), progress_bar(nsteps, label) as bar:
                diverged = play_script(sim, script, rec, progress=bar.update, stop=stop)
                if diverged is not None:  # the end marker says so; compile warns
                    saved = f"; the recording up to there is kept: {out}" if out else ""
                    raise click.ClickException(f"{diverged}{saved}")
    except OSError as e:
        if out is None:
            raise
        removed = not existed and remove_partial(out)
        raise UserError(str(output_error(out, e)) + (" (partial file removed)" if removed else "")) from None
    if rec is not None:  # the simulation's plausibility (docs/recordings.md)
        for ep in rec.plausibility.episodes:
            click.echo(f"warning: implausible simulation: {ep.text()}", err=True)
    if stop is not None and stop.signum is not None and rec is not None:
        kept = f"recording kept: {out}, {rec.duration:.3f} s of simulated time"
        click.echo(f"interrupted ({stop.name}): {kept}", err=True)
        raise SystemExit(stop.exit_code)
    return sim.tracker


def _scene_and_script(scene_ref: str | None, script_path: str | None) -> tuple[Any, Any]:
    """The scene and script of a demonstration (see :func:`demonstrate`)."""
    from dlovr.script import load_script

    if script_path is None:
        if scene_ref is None:
            raise UserError("give --scene NAME|PATH or --script FILE")
        return load_scene_arg(scene_ref), load_script(builtin_script(scene_ref))
    script = load_script(script_path)
    return script_scene(script, scene_ref), script


def _simulator(scene: Any) -> Any:
    """A tracking simulator of ``scene``; a scene MuJoCo refuses is one line naming its file."""
    from dlovr.sim import Simulator

    try:
        return Simulator(scene, track=True)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None


def _recorder(out: str | None, scene: Any, sim: Any, force: bool) -> Any:
    """A recorder of the demonstration to ``out``, or None."""
    from dlovr.recording import DemoRecorder

    return DemoRecorder(out, scene, sim, sim.tracker, overwrite=force) if out else None


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
                "t": rounded_time(kept.start),
                "duration": rounded_time(kept.duration),
                "topological": st.topological.format() if st else "",
                "discrete": kept.situation.format(),
                "classes": list(classes),
            }
        )
    return rows


@click.command("demo", short_help="Run a built-in demonstration headless, print its states.")
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
@click.option("-f", "--force", is_flag=True, help="Overwrite the -o file if it exists.")
@finishes_on_sigterm
def demo_cmd(scene_ref: str, script_path: str | None, out: str | None, as_json: bool, force: bool) -> None:
    """Run a built-in demonstration headless and print its contact situations (Fig. 11 style).

    With -o FILE it is recorded too; an existing FILE is refused unless --force.
    """
    import json

    if out is not None:
        refuse_existing(out, force)
    if scene_ref is None and script_path is None:
        scene_ref = "peg_in_hole"
    warm_up()
    tracker = demonstrate(scene_ref, script_path, out, f"demo {scene_ref or script_path}", force)
    rows = _kept_rows(tracker)
    click.echo(json.dumps(rows, indent=2) if as_json else _states_table(rows))


@click.command("record", short_help="Record a scripted demonstration (or N perturbed ones) to MCAP.")
@click.option("--scene", "scene_ref", help="Built-in scene name or path (default: the script's scene).")
@click.option(
    "--script", "script_path", required=True, type=click.Path(dir_okay=False), help="Script (TOML)."
)
@click.option(
    "-o",
    "--output",
    "out",
    required=True,
    type=click.Path(),
    help="Output MCAP file (with --trials: a directory).",
)
@click.option("-f", "--force", is_flag=True, help="Overwrite the output file if it exists.")
@click.option("--trials", type=click.IntRange(min=1), help="Record N demonstrations in perturbed scenes.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Seed of the trials.")
@click.option("--vary", "varies", multiple=True, metavar="KEY=SPEC",
              help="Perturb, as `dlovr run --vary`; demo.KEY=LEVEL: a person's motion (docs/people.md).")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True, help="Processes.")
@cluster_option
@finishes_on_sigterm
def record_cmd(
    scene_ref: str | None,
    script_path: str,
    out: str,
    force: bool,
    trials: int | None,
    seed: int,
    varies: tuple[str, ...],
    workers: int,
    cluster: str | None,
) -> None:
    """Record a scripted demonstration headless to an MCAP file.

    An existing output file is refused unless --force. Ctrl-C or SIGTERM end the recording between
    two steps: the file is kept, finished, and replays and verifies (`dlovr replay --verify`).

    With --trials N -o DIR: N demonstrations, each in the scene perturbed by --vary (the syntax and
    draws of `dlovr run --vary`, deterministic from --seed), as DIR/demo_KKK.mcap with DIR/demos.json;
    --vary demo.KEY=LEVEL plays the script with a person's motion (drift, tremor, pace, key jog:
    docs/people.md; demo.person=1 for the defaults);
    on --workers local processes or, with --cluster, on Ray. `dlovr network DIR` merges them.

    Exit status: 0 done; 2 bad input; 1 the simulation diverged (the recording is kept up to there;
    with --trials: any demonstration diverged or could not start);
    130 (Ctrl-C, SIGINT) or 143 (SIGTERM) interrupted, the recording so far kept.
    """
    if trials is None:
        if varies or cluster:
            raise UserError("--vary and --cluster need --trials N")
        if os.path.isdir(out):
            raise UserError(f"{out}: is a directory (a directory of recordings needs --trials N)")
        refuse_existing(out, force)
        tracker = demonstrate(scene_ref, script_path, out, "recording", force)
        click.echo(f"wrote {out}: {plural(len(tracker.kept), 'contact situation')}")
        return
    _record_trials(scene_ref, script_path, out, force, trials, seed, varies, workers, cluster)


def _record_trials(
    scene_ref: str | None,
    script_path: str,
    out: str,
    force: bool,
    n: int,
    seed: int,
    varies: tuple[str, ...],
    workers: int,
    cluster: str | None,
) -> None:
    from pathlib import Path

    from dlovr.execution.demo_sets import DemoSetup, demo_path, record_demos
    from dlovr.execution.variation import parse_varies
    from dlovr.geometry import scene_pieces
    from dlovr.outputs import check_writable_dir
    from dlovr.recording.bundle import SceneBundle
    from dlovr.script import load_script

    script = load_script(script_path)
    scene = script_scene(script, scene_ref)
    variations = parse_varies(varies, scene, demo=True)
    if os.path.exists(out) and not os.path.isdir(out):
        raise UserError(f"{out}: exists and is not a directory")
    setup = DemoSetup(
        scene,
        scene_pieces(scene),
        script,
        variations,
        seed,
        str(Path(out).resolve()),
        SceneBundle.from_path(scene.path).digest,
        force,
    )
    index = Path(setup.out_dir) / "demos.json"
    existing = [p for p in [*(demo_path(setup, k) for k in range(n)), index] if os.path.lexists(p)]
    if existing and not force:
        raise UserError(f"{existing[0]}: exists; give --force to overwrite the demonstrations")
    check_writable_dir(out)  # before the batch: a folder that takes no file fails now, not after it
    try:
        demos = record_demos(setup, n, workers=workers, cluster=cluster, progress=True)
    except (KeyboardInterrupt, SystemExit) as e:
        _interrupted_demos(e, setup, n, out)
        raise
    _write_index(setup, demos, out)
    bad = [d for d in demos if d["error"]]
    for d in bad:
        click.echo(f"demo {d['trial']}: {d['error']}", err=True)
    retried = sum(d["attempts"] > 1 for d in demos)
    wrote = sum(d["path"] is not None for d in demos)
    click.echo(
        f"wrote {wrote} recordings of {scene.name} to {shown_dir(out)} (demos.json): {len(bad)} diverged or "
        f"failed, {retried} retried"
    )
    if bad:
        raise SystemExit(EXIT_FAILED)


def _write_index(setup: Any, demos: list[dict[str, Any]], out: str) -> None:
    """``DIR/demos.json`` (:func:`dlovr.execution.demo_sets.write_index`); a failed write is one line
    (the recordings themselves are on disk already)."""
    from dlovr.execution.demo_sets import write_index
    from dlovr.outputs import OutputError, describe_os_error

    kept = sum(d["path"] is not None for d in demos)
    try:
        write_index(setup, demos)
    except OutputError as e:
        raise UserError(f"{e} ({kept} recordings kept in {shown_dir(out)})") from None
    except OSError as e:
        where = e.filename or shown_dir(out) + "demos.json"
        why = describe_os_error(e)
        kept_in = f"{kept} recordings kept in {shown_dir(out)}"
        raise UserError(f"{where}: cannot write: {why} ({kept_in})") from None


def _interrupted_demos(e: BaseException, setup: Any, n: int, out: str) -> None:
    """A signal ended ``record --trials``: the finished demonstrations go into demos.json (the one
    in progress was finished by its worker, shorter), one line, exit 130 or 143. (Another
    ``SystemExit`` returns: the caller re-raises it.)"""
    import signal

    from dlovr import signals
    from dlovr.batch import finished

    if isinstance(e, SystemExit) and not isinstance(e, signals.SignalExit) and signals.pending() is None:
        return
    demos = [
        {**r.value, "attempts": r.attempts} if r.ok else
        {"trial": r.index, "seed": setup.seed, "path": None, "error": str(r.error), "situations": 0,
         "attempts": r.attempts}
        for r in sorted(finished(e), key=lambda r: r.index)
    ]
    if demos:
        _write_index(setup, demos, out)
    signum = signals.pending() or (signal.SIGINT if isinstance(e, KeyboardInterrupt) else signal.SIGTERM)
    listed = f"listed in {shown_dir(out)}demos.json" if demos else "none listed"
    click.echo(f"\ninterrupted ({signals.name(signum)}): {len(demos)} of {n} demonstrations finished, "
               f"{listed} (a recording in progress is kept, finished where it stopped)", err=True)
    signals.clear()
    raise SystemExit(signals.exit_code(signum))


@click.command("replay", short_help="Re-simulate a recording, or verify it bit for bit.")
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("--verify", is_flag=True, help="Compare every checkpoint bit for bit and the contact states.")
@finishes_on_sigterm
def replay_cmd(recording: str, verify: bool) -> None:
    """Re-simulate a recording from its embedded scene and command stream.

    Exit status: 0 replayed (with --verify: bit-identical); 1 with --verify: the replay diverged from
    the recording; 2 the recording cannot be read (damaged, not a recording, ...).
    """
    from dlovr.recording import replay

    freeze_setup()
    with progress_bar(1, "replay") as bar:
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
            note = _recovery_note(recording)
            if note:  # the damage, not the simulation: bad input
                raise UserError(f"{recording}: replay diverged: {res.divergence}{note}")
            raise click.ClickException(f"{recording}: replay diverged: {res.divergence}")
        click.echo("verified: every checkpoint bit-identical, contact states identical")


def _recovery_note(recording: str) -> str:
    """What ``dlovr recover`` skipped when it wrote ``recording`` (see ``Recording.recovery_note``)."""
    from dlovr.recording import Recording

    return Recording(recording).recovery_note


@click.command("states", short_help="Print a recording's contact situations and transitions.")
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option(
    "--format", "fmt", type=click.Choice(["table", "json", "csv"]), default="table", show_default=True
)
@click.option("--raw", is_flag=True, help="Every recorded change, not debounced.")
@finishes_on_sigterm
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
                "t": rounded_time(p["t"]),
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
                "t": rounded_time(k.t),
                "duration": rounded_time(k.duration),
                "topological": k.topological or "",
                "discrete": k.situation.format(),
                "classes": list(classes),
            }
            for k, classes in zip(kept, kept_classes(kept), strict=True)
        ]
    for ep in rec.warnings():  # on stderr: the table, JSON or CSV on stdout stays as it is
        click.echo(f"warning: implausible simulation: {ep.text()}", err=True)
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


@click.command("recover", short_help="Rescue a recording whose writer was killed.")
@click.argument("broken", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "out", required=True, type=click.Path(dir_okay=False), help="Recovered file.")
@click.option("-f", "--force", is_flag=True, help="Overwrite the output file if it exists.")
@finishes_on_sigterm
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
    refuse_existing(out, force)
    with atomic_output(out, force=force) as tmp:  # no partial file at ``out`` if writing fails
        rep = recover(broken, tmp)
    click.echo(
        f"wrote {out}: {plural(rep.messages, 'message')}, {plural(rep.attachments, 'attachment')}, "
        f"{rep.last_time_s:.2f} s"
    )
    for line in rep.skipped:
        click.echo(f"skipped {line}", err=True)
