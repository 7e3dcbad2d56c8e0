"""Command-line interface: ``dlovr …`` (click).

Each command validates its input and reports a problem as one line naming the file and the problem,
with exit code 2 and no traceback.
"""

from __future__ import annotations

import click

from dlovr import __version__


class UserError(click.ClickException):
    """A problem with the user's input: printed as one line, exit code 2."""

    exit_code = 2


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="dlovr")
def main() -> None:
    """dlovr: demonstrate DLO (cable) manipulation, extract contact states, compile programs."""


# --------------------------------------------------------------------------------------------------
# dlovr transitions
# --------------------------------------------------------------------------------------------------


def _load_facts(path: str) -> tuple[object, dict[int, tuple[float, float, float]]]:
    """Read a facts JSON file: face normals, face-pair relations and DLO vectors by point index."""
    import json

    from dlovr.model.discrete import FaceFact, FactBook, PairFact

    try:
        with open(path, encoding="utf-8") as fh:
            raw = json.load(fh)
    except OSError as e:
        raise UserError(f"{path}: cannot read facts file: {e.strerror}") from None
    except json.JSONDecodeError as e:
        raise UserError(f"{path}: not valid JSON: {e.msg} at line {e.lineno}") from None
    try:
        faces = {
            name: FaceFact(
                name, name.rpartition(".")[0], tuple(map(float, f["normal"])), bool(f.get("internal"))
            )
            for name, f in raw.get("faces", {}).items()
        }
        pairs = [
            PairFact(p["a"], p["b"], bool(p["concave"]), float(p["opening_deg"]), None)
            for p in raw.get("pairs", [])
        ]
        vectors = {int(k): tuple(map(float, v)) for k, v in raw.get("dlo_vectors", {}).items()}
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise UserError(f"{path}: bad facts file: {e!r}") from None
    return FactBook(faces, pairs), vectors  # type: ignore[return-value]


@main.command("transitions")
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@click.option("--unicode/--ascii", default=False, help="Notation in the table (default ASCII).")
@click.option(
    "--facts",
    type=click.Path(dir_okay=False),
    help="JSON with face normals, face-pair relations and DLO vectors, needed for topological lines.",
)
def transitions_cmd(file: str, as_json: bool, unicode: bool, facts: str | None) -> None:
    """Classify the transitions of a sequence of situations, one per line of FILE.

    Lines hold discrete situations (``V/G & E/N & V/F[box.F1]``) or topological ones
    (``VS/G & E3/N & VE/box.F1``, which need --facts); ``#`` starts a comment.
    """
    import dataclasses
    import json

    from dlovr.model.discrete import DiscreteSituation, ModelParams, discretize, parse_any
    from dlovr.model.topology import NotationError, Situation
    from dlovr.model.transitions import classify_sequence

    try:
        with open(file, encoding="utf-8") as fh:
            lines = fh.read().splitlines()
    except OSError as e:
        raise UserError(f"{file}: cannot read: {e.strerror}") from None
    except UnicodeDecodeError:
        raise UserError(f"{file}: not a UTF-8 text file") from None
    book_vectors = _load_facts(facts) if facts else None
    rows: list[tuple[int, Situation | None, DiscreteSituation]] = []
    for lineno, line in enumerate(lines, 1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        try:
            sit = parse_any(text)
        except NotationError as e:
            raise UserError(f"{file}:{lineno}: {e}") from None
        if isinstance(sit, DiscreteSituation):
            rows.append((lineno, None, sit))
            continue
        if book_vectors is None:
            raise UserError(
                f"{file}:{lineno}: a topological situation needs geometric facts: give --facts FILE"
            )
        book, vectors = book_vectors
        contacts = tuple(
            dataclasses.replace(c, dlo=dataclasses.replace(c.dlo, vector=vectors.get(c.dlo.index)))
            if c.dlo.index is not None
            else c
            for c in sit.contacts
        )
        try:
            disc = discretize(Situation(contacts), book, ModelParams())  # type: ignore[arg-type]
        except (KeyError, ValueError) as e:
            msg = e.args[0] if e.args else repr(e)
            raise UserError(f"{file}:{lineno}: cannot classify {sit}: {msg}") from None
        rows.append((lineno, sit, disc))
    if not rows:
        raise UserError(f"{file}: no situations (every line is empty or a comment)")
    steps = classify_sequence([r[2] for r in rows])
    if as_json:
        out = [
            {
                "step": s.index + 1,
                "line": r[0],
                "topological": r[1].format() if r[1] is not None else None,
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


# --------------------------------------------------------------------------------------------------
# Simulation, recording, replay, programs
# --------------------------------------------------------------------------------------------------


def _scene(ref: str):
    from dlovr.scene import SceneError, load_scene

    try:
        return load_scene(ref)
    except SceneError as e:
        raise UserError(str(e)) from None


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


def run_demonstration(scene_ref: str | None, script_path: str | None, out: str | None, label: str):
    """Run a scripted demonstration headless (optionally recording it); return (scene, tracker)."""
    from contextlib import nullcontext

    from dlovr.recording import DemoRecorder, finish_on_sigterm
    from dlovr.sim import SimulationDiverged, Simulator

    if script_path is None:
        if scene_ref is None:
            raise UserError("give --scene NAME|PATH or --script FILE")
        script_path = _builtin_script(scene_ref)
    script = _script(script_path)
    scene = _scene(scene_ref or script.scene or "table")
    try:
        sim = Simulator(scene, track=True)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None
    tracker = sim.tracker
    nsteps = round(script.total_duration / sim.model.opt.timestep)
    with finish_on_sigterm():
        recorder = DemoRecorder(out, scene, sim, tracker) if out else nullcontext()
        with recorder as rec, _progress(nsteps, label) as bar:
            try:
                for k, record in enumerate(sim.run(script), 1):
                    if rec is not None:
                        rec.step(record)
                    if k % 100 == 0:
                        bar.update(100)
            except SimulationDiverged as e:
                saved = f" (recording kept up to there: {out})" if out else ""
                raise click.ClickException(f"simulation diverged: {e}{saved}") from None
    return scene, tracker


def _warm_up() -> None:
    """Compile the per-step kernels on the first run, saying so (on stderr)."""
    from dlovr.sim.warmup import warm_up

    warm_up(lambda notice: click.echo(notice, err=True))


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
                "t": kept.start,
                "duration": kept.duration,
                "topological": st.topological.format() if st else "",
                "discrete": kept.situation.format(),
                "classes": list(classes),
            }
        )
    return rows


@main.command("demo")
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
def demo_cmd(scene_ref: str, script_path: str | None, out: str | None, as_json: bool) -> None:
    """Run a built-in demonstration headless and print its contact situations (Fig. 11 style)."""
    import json

    if scene_ref is None and script_path is None:
        scene_ref = "peg_in_hole"
    _warm_up()
    _, tracker = run_demonstration(scene_ref, script_path, out, f"demo {scene_ref or script_path}")
    rows = _kept_rows(tracker)
    click.echo(json.dumps(rows, indent=2) if as_json else _states_table(rows))


@main.command("record")
@click.option("--scene", "scene_ref", help="Built-in scene name or path (default: the script's scene).")
@click.option(
    "--script", "script_path", required=True, type=click.Path(dir_okay=False), help="Script (TOML)."
)
@click.option(
    "-o", "--output", "out", required=True, type=click.Path(dir_okay=False), help="Output MCAP file."
)
def record_cmd(scene_ref: str | None, script_path: str, out: str) -> None:
    """Record a scripted demonstration headless to an MCAP file."""
    _, tracker = run_demonstration(scene_ref, script_path, out, "recording")
    click.echo(f"wrote {out}: {len(tracker.kept)} contact situations")


def _recording_error(fn):
    import functools

    from dlovr.recording import RecordingError

    @functools.wraps(fn)
    def wrapper(*a, **kw):
        try:
            return fn(*a, **kw)
        except RecordingError as e:
            raise UserError(str(e)) from None

    return wrapper


@main.command("replay")
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option("--verify", is_flag=True, help="Compare every checkpoint bit for bit and the contact states.")
@_recording_error
def replay_cmd(recording: str, verify: bool) -> None:
    """Re-simulate a recording from its embedded scene and command stream."""
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


@main.command("states")
@click.argument("recording", type=click.Path(dir_okay=False))
@click.option(
    "--format", "fmt", type=click.Choice(["table", "json", "csv"]), default="table", show_default=True
)
@click.option("--raw", is_flag=True, help="Every recorded change, not debounced.")
@_recording_error
def states_cmd(recording: str, fmt: str, raw: bool) -> None:
    """Print a recording's contact situations and transitions (reads only the contact-state channel)."""
    import csv
    import io
    import json

    from dlovr.model.transitions import classify_step
    from dlovr.recording import Recording, kept_states

    rec = Recording(recording)
    if raw:
        rows = [
            {
                "t": p["t"],
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
                "t": k.t,
                "duration": k.duration,
                "topological": k.topological or "",
                "discrete": k.situation.format(),
                "classes": list(classify_step(kept[i - 1].situation, k.situation)) if i else [],
            }
            for i, k in enumerate(kept)
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


@main.command("recover")
@click.argument("broken", type=click.Path(dir_okay=False))
@click.option("-o", "--output", "out", required=True, type=click.Path(dir_okay=False), help="Recovered file.")
@_recording_error
def recover_cmd(broken: str, out: str) -> None:
    """Rescue every complete chunk of a recording whose writer was killed."""
    from dlovr.recording import recover

    rep = recover(broken, out)
    click.echo(
        f"wrote {out}: {rep.messages} messages, {rep.attachments} attachments, {rep.last_time_s:.2f} s"
    )


# --------------------------------------------------------------------------------------------------
# dlovr scenes, dlovr scene show (issue 3)
# --------------------------------------------------------------------------------------------------


@main.command("scenes")
def scenes_cmd() -> None:
    """List the built-in scenes (use them by name, e.g. ``dlovr scene show peg_in_hole``)."""
    from dlovr.scene import builtin_scenes

    rows = builtin_scenes()
    width = max((len(n) for n, _ in rows), default=4)
    for name, desc in rows:
        click.echo(f"{name:<{width}}  {desc}")


@main.group("scene")
def scene_group() -> None:
    """Inspect scenes: built-in ones by name, others by the path of their TOML file."""


@scene_group.command("show")
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


@main.command("compile")
@click.argument("inputs", nargs=-1, required=True, type=click.Path())
@click.option(
    "-o", "--output-dir", type=click.Path(file_okay=False), help="Where programs go (default: beside each)."
)
@click.option("--workers", type=click.IntRange(1, 64), default=1, show_default=True, help="Worker processes.")
@click.option("--force", is_flag=True, help="Recompile unchanged recordings too.")
def compile_cmd(inputs: tuple[str, ...], output_dir: str | None, workers: int, force: bool) -> None:
    """Compile recordings (files or directories of *.mcap) into macro programs (JSON + text listing)."""
    from concurrent.futures import ProcessPoolExecutor

    from dlovr.recording import compile_one, find_recordings, record_compiled

    paths = find_recordings(inputs)
    if not paths:
        raise UserError(f"no recordings found in {', '.join(inputs)}")
    results = []
    with _progress(len(paths), "compiling") as bar:
        if workers == 1:
            for p in paths:
                results.append(compile_one(str(p), output_dir, force))
                bar.update(1)
        else:
            with ProcessPoolExecutor(max_workers=workers) as pool:
                futures = [pool.submit(compile_one, str(p), output_dir, force) for p in paths]
                for f in futures:
                    results.append(f.result())
                    bar.update(1)
    record_compiled(results, output_dir)
    failed = [r for r in results if r.error]
    for r in results:
        if r.error:
            click.echo(f"FAILED {r.error}", err=True)
        else:
            note = " (unchanged, skipped)" if r.skipped else ""
            click.echo(f"{r.path} -> {r.json_path}: {r.macros} macros, {r.risky} risky{note}")
    ok = len(results) - len(failed)
    click.echo(f"{ok} compiled, {len(failed)} failed")
    if failed:
        raise SystemExit(1)


@scene_group.command("export")
@click.argument("ref", metavar="NAME|PATH")
@click.option(
    "-o", "--output", "out", required=True, type=click.Path(dir_okay=False), help="MJCF file to write."
)
def scene_export_cmd(ref: str, out: str) -> None:
    """Write the scene's compiled MuJoCo model (MJCF, meshes inline), loadable by plain MuJoCo."""
    from dlovr.sim import Simulator, export_xml

    scene = _scene(ref)
    try:
        sim = Simulator(scene)
    except ValueError as e:
        raise UserError(f"{scene.path}: {e}") from None
    try:
        path = export_xml(sim.built, out)
    except OSError as e:
        raise UserError(f"{out}: cannot write: {e.strerror}") from None
    click.echo(f"wrote {path}")


# --------------------------------------------------------------------------------------------------
# dlovr serve (issue 6)
# --------------------------------------------------------------------------------------------------


@main.command("serve")
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
