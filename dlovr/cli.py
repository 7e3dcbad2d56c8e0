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

    from dlovr.discrete import FaceFact, FactBook, PairFact

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

    from dlovr.discrete import DiscreteSituation, ModelParams, discretize, parse_any
    from dlovr.topology import NotationError, Situation
    from dlovr.transitions import classify_sequence

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
