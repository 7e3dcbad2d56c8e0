"""``dlovr transitions``: classify a hand-written sequence of situations (registered on the main group
by :mod:`dlovr.cli`)."""

from __future__ import annotations

from typing import Any

import click

from dlovr.cli.common import FiniteFloat, UserError


@click.command("transitions", short_help="Classify a hand-written sequence of situations.")
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@click.option("--unicode/--ascii", default=False, help="Notation in the table (default ASCII).")
@click.option(
    "--facts",
    type=click.Path(dir_okay=False),
    help="JSON with face normals, face-pair relations and DLO vectors, needed for topological lines.",
)
@click.option("--hold", type=FiniteFloat(0.0), help="Timed input: hold time, s (default 0.01).")
@click.option("--flight", type=FiniteFloat(0.0), help="Timed input: flight time, s (default 0.3).")
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
    from dlovr.facts import load_facts
    from dlovr.inputs import read_text
    from dlovr.model.sequence import SequenceError, parse_sequence

    lines = read_text(file, what="sequence file").splitlines()
    book, vectors = load_facts(facts) if facts else (None, None)
    try:
        rows = parse_sequence(lines, book, vectors)
    except SequenceError as e:
        raise UserError(f"{file}:{e.line}: {e}" if e.line else f"{file}: {e}") from None
    if rows[0].t is None:
        if hold is not None or flight is not None:
            raise UserError(f"{file}: --hold and --flight debounce timed input; no line starts with a time")
        _untimed(rows, as_json, unicode)
    else:
        _timed(rows, hold, flight, as_json, unicode)


def _untimed(rows: list[Any], as_json: bool, unicode: bool) -> None:
    """Print the classes of an untimed sequence, one row per line."""
    import json

    from dlovr.model.transitions import classify_sequence

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


def _timed(rows: list[Any], hold: float | None, flight: float | None, as_json: bool, unicode: bool) -> None:
    """Debounce a timed sequence (hold and flight times in s) and print its kept situations' classes."""
    import json

    from dlovr.model.sequence import debounce_sequence
    from dlovr.model.transitions import DEFAULT_FLIGHT_S, DEFAULT_HOLD_S, format_classes

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
