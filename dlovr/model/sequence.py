"""Sequences of contact situations written one per line, untimed or timed (``dlovr transitions``).

Pure Python. A line holds a discrete situation (``V/G & E/N & V/F[box.F1]``) or a topological one
(``VS/G & E3/N & VE/box.F1``, classified with geometric facts), optionally after a time in seconds
(``0.012  V/G & E/N & V/N``); ``#`` starts a comment. Either every line of a file starts with a time
or none does. A timed sequence is debounced like a simulation's (:class:`Debouncer`: flicker,
brief intermediate states, flights) before it is classified, so logs of other systems are
classified the way a simulation is (docs/model.md).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from dlovr.inputs import InputError
from dlovr.model.discrete import (
    DiscreteSituation,
    FactBook,
    ModelParams,
    Vec3,
    discretize,
    parse_any,
)
from dlovr.model.topology import NotationError, Situation
from dlovr.model.transitions import (
    DEFAULT_FLIGHT_S,
    DEFAULT_HOLD_S,
    Debouncer,
    Kept,
    is_transient,
    kept_classes,
)

_TIMED_RE = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s+(\S.*)$")


class SequenceError(InputError):
    """A line of a sequence cannot be read: ``line`` is its number (1-based, 0 for the whole file)."""

    def __init__(self, line: int, message: str):
        super().__init__(message)
        self.line = line


@dataclass(frozen=True)
class SequenceLine:
    """One situation of a sequence: its line number, time (s, ``None`` when untimed), the topological
    situation it was written as (``None`` for a discrete line) and its discrete situation."""

    line: int
    t: float | None
    topological: Situation | None
    discrete: DiscreteSituation


@dataclass(frozen=True)
class KeptLine:
    """A kept situation of a timed sequence, the line where it began, and the classes of the
    transition into it (``through_free``: reached by a flight)."""

    kept: Kept[DiscreteSituation]
    line: SequenceLine
    classes: tuple[str, ...]


def split_time(text: str) -> tuple[float | None, str]:
    """``"0.012  V/G & E/N & V/N"`` -> ``(0.012, "V/G & E/N & V/N")``; untimed -> ``(None, text)``."""
    m = _TIMED_RE.match(text)
    return (float(m.group(1)), m.group(2)) if m else (None, text)


def parse_sequence(
    lines: Sequence[str],
    book: FactBook | None = None,
    vectors: Mapping[int, Vec3] | None = None,
    params: ModelParams | None = None,
) -> list[SequenceLine]:
    """Read a sequence, one situation per line (comments and blank lines skipped).

    ``book`` and ``vectors`` (DLO vectors by point index) are the geometric facts that topological
    lines need. Raises :class:`SequenceError` naming the first bad line: bad notation, a topological
    line without facts, timed and untimed lines mixed, a time that is not finite or goes back.
    """
    out: list[SequenceLine] = []
    for lineno, raw in enumerate(lines, 1):
        text = raw.split("#", 1)[0].strip()
        if not text:
            continue
        t, text = split_time(text)
        if out and (t is None) != (out[0].t is None):
            first = out[0].line
            has = "has one" if t is None else "has none"
            what = "no time at the start of the line" if t is None else "a time"
            raise SequenceError(
                lineno, f"{what}, but line {first} {has}: either every line starts with a time or none does"
            )
        if t is not None:
            if not math.isfinite(t):
                raise SequenceError(lineno, f"time {t} is not a finite number of seconds")
            before = out[-1].t if out else None  # timed too (checked above)
            if before is not None and t < before:
                raise SequenceError(lineno, f"time {t:g} s is before the previous line's {before:g} s")
        try:
            sit = parse_any(text)
        except NotationError as e:
            raise SequenceError(lineno, str(e)) from None
        if isinstance(sit, DiscreteSituation):
            out.append(SequenceLine(lineno, t, None, sit))
            continue
        if book is None:
            raise SequenceError(lineno, "a topological situation needs geometric facts: give --facts FILE")
        vec = vectors or {}
        contacts = tuple(
            dataclasses.replace(c, dlo=dataclasses.replace(c.dlo, vector=vec.get(c.dlo.index)))
            if c.dlo.index is not None
            else c
            for c in sit.contacts
        )
        try:
            disc = discretize(Situation(contacts), book, params or ModelParams())
        except (KeyError, ValueError) as e:
            msg = e.args[0] if e.args else repr(e)
            raise SequenceError(lineno, f"cannot classify {sit}: {msg}") from None
        out.append(SequenceLine(lineno, t, sit, disc))
    if not out:
        raise SequenceError(0, "no situations (every line is empty or a comment)")
    return out


def debounce_sequence(
    rows: Sequence[SequenceLine], hold: float = DEFAULT_HOLD_S, flight: float = DEFAULT_FLIGHT_S
) -> list[KeptLine]:
    """Debounce a timed sequence (hold and flight times in seconds) and classify its kept situations."""
    timed = [(r.t, r) for r in rows if r.t is not None]
    if len(timed) != len(rows):
        raise ValueError("only a timed sequence is debounced")
    deb: Debouncer[DiscreteSituation] = Debouncer(hold, is_transient, flight)
    first: dict[tuple[float, DiscreteSituation], SequenceLine] = {}
    for t, r in timed:
        deb.push(t, r.discrete)
        first.setdefault((t, r.discrete), r)
    kept = deb.kept
    return [
        KeptLine(k, first[(k.start, k.situation)], c) for k, c in zip(kept, kept_classes(kept), strict=True)
    ]
