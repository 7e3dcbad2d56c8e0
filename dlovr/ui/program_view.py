"""A compiled program as the recording panel shows it (no viser): one row per macro with its class,
the principal contact that changes (from -> to), a risk colour, and, for a risky program, why.

The macros are read tolerantly (``getattr`` with fallbacks), so the view works with the program
format of :mod:`dlovr.model.program` as it stands and as it grows: a ``risk`` field (none / caution /
risky) where present, else the classes (``I``, ``S`` risky, ``T`` caution, paper §IV.B and §VI); the
principal change where the macro names it, else the whole situations; a final macro without a class.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dlovr.model.transitions import CLASS_NAMES, format_classes

RISK_COLORS = {"none": "#8c8c8c", "caution": "#7b4fb0", "risky": "#c2185b"}
"""Risk colours: grey, purple, magenta, and a shape each (:data:`RISK_SYMBOLS`), so that they are not
read as the cable's stability colours (green, yellow, red)."""
RISK_SYMBOLS = {"none": "&#9675;", "caution": "&#9650;", "risky": "&#9888;"}
RISKY_CLASSES = ("I", "S")
CAUTION_CLASSES = ("T",)
WHY = {
    "I": "the cable enters an instable contact (I), which the next motion may lose",
    "S": "a spontaneous transition (S): the cable snaps or flies, only a high-rate force sensor sees it",
    "T": "a transient transition (T) through a semi-stable contact",
}

# names the principal change may carry in the program format, most specific first
_FROM_NAMES = ("change_from", "principal_from", "from_principal", "changed_from")
_TO_NAMES = ("change_to", "principal_to", "to_principal", "changed_to")


def macro_classes(m: Any) -> tuple[str, ...]:
    return tuple(str(c) for c in (getattr(m, "classes", None) or ()))


def macro_risk(m: Any) -> str:
    """``none``, ``caution`` or ``risky``: the macro's own ``risk`` where it has one, else from its
    classes (and the older ``risky`` flag)."""
    r = getattr(m, "risk", None)
    r = getattr(r, "value", r)  # an enum
    if isinstance(r, str) and r.lower() in RISK_COLORS:
        return r.lower()
    classes = macro_classes(m)
    if getattr(m, "risky", False) is True or any(c in RISKY_CLASSES for c in classes):
        return "risky"
    if any(c in CAUTION_CLASSES for c in classes):
        return "caution"
    return "none"


def _text(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, str):
        return v
    fmt = getattr(v, "format", None)
    if callable(fmt):
        try:
            return str(fmt())
        except TypeError:
            pass
    state = getattr(v, "state", None)  # a ContactSpec
    if isinstance(state, str):
        return state
    if isinstance(v, Sequence):
        return ", ".join(_text(x) for x in v)
    return str(v)


def macro_change(m: Any) -> tuple[str, str]:
    """(from, to): the principal contact that changes where the macro names it, else the situations."""
    for a, b in zip(_FROM_NAMES, _TO_NAMES, strict=True):
        f, t = getattr(m, a, None), getattr(m, b, None)
        if f is not None or t is not None:
            return _text(f) or "-", _text(t) or "-"
    change = getattr(m, "change", None)
    if change is not None and (hasattr(change, "from_") or hasattr(change, "to")):
        return _text(getattr(change, "from_", None)) or "-", _text(getattr(change, "to", None)) or "-"
    a, b = _text(getattr(m, "from_situation", "")), _text(getattr(m, "to_situation", ""))
    return _changed_part(a, b) if a and b else (a or "-", b or "-")


def _changed_part(a: str, b: str) -> tuple[str, str]:
    """The contacts of two situations (``c1 & c2 & ...``) that differ, the common ones at either end
    left out (shown as ``…``)."""
    ca, cb = a.split(" & "), b.split(" & ")
    i = 0
    while i < min(len(ca), len(cb)) - 1 and ca[i] == cb[i]:
        i += 1
    j = 0
    while j < min(len(ca), len(cb)) - 1 - i and ca[-1 - j] == cb[-1 - j]:
        j += 1
    if i == 0 and j == 0:
        return a, b

    def part(c: list[str]) -> str:
        mid = c[i : len(c) - j] or ["(none)"]
        return " & ".join((["…"] if i else []) + mid + (["…"] if j else []))

    return part(ca), part(cb)


def macro_label(m: Any) -> str:
    classes = macro_classes(m)
    if classes:
        return format_classes(classes)
    return "final" if getattr(m, "final", True) else "-"


def risk_reasons(program: Any) -> list[str]:
    """One sentence per risky macro: which macro, which class, what that means."""
    out = []
    for k, m in enumerate(getattr(program, "macros", ()) or (), start=1):
        if macro_risk(m) != "risky":
            continue
        idx = getattr(m, "index", k)
        why = [WHY[c] for c in macro_classes(m) if c in RISKY_CLASSES] or ["marked risky by the compiler"]
        out.append(f"macro {idx} ({macro_label(m)}, t = {getattr(m, 't', 0.0):.2f} s): " + "; ".join(why))
    return out


_WRAP = "padding:1px 4px;overflow-wrap:anywhere;word-break:break-all"
"""The change column breaks anywhere: a long face list (``V/VI[block.F3,block.F5,...]``) must not widen
the table past the panel, which cannot scroll sideways (the risk column would be cut off)."""

OUTCOME_MARKS = {
    "ok": ("&#10003;", "#2e9e44", "transition detected (or the motion done)"),
    "went on": ("&#8631;", "#e08a00", "nothing felt: went on with the demonstrated motion"),
    "failed": ("&#10007;", "#d62728", "failed"),
}
"""The marks of the macros a run ended (symbol, colour, what it means, as the key under the table says
it): detected (or its motion done), not felt and gone on with the demonstrated motion (a hand's
program), failed."""
CURRENT_BACKGROUND = "#ffe58a"


def program_html(
    program: Any,
    files: Sequence[tuple[str, str | Path]] = (),
    *,
    current: int | None = None,
    outcomes: Mapping[int, str] | None = None,
) -> str:
    """The program as an HTML table (class, from -> to, risk), the files (label, path) and, when it has
    risky macros, why; ``data-risk`` on each row names its risk for tests and styling.

    While the program runs: the row of macro ``current`` (its index) is highlighted
    (``data-current="1"``), and ``outcomes`` (macro index -> ``ok``, ``went on`` or ``failed``) marks
    the macros that ended (``data-outcome``), the marks explained under the table."""
    macros = list(getattr(program, "macros", ()) or ())
    outcomes = outcomes or {}
    rows = []
    for k, m in enumerate(macros, start=1):
        risk = macro_risk(m)
        a, b = macro_change(m)
        classes = macro_classes(m)
        idx = getattr(m, "index", k)
        tip = html.escape("; ".join(CLASS_NAMES.get(c, c) for c in classes) or "motion to the end pose")
        attrs = f' data-macro="{idx}"'
        if idx == current:
            attrs += f' data-current="1" style="background:{CURRENT_BACKGROUND}"'
        mark = ""
        if idx in outcomes:
            sym, color, _ = OUTCOME_MARKS.get(outcomes[idx], ("?", "#888", ""))
            attrs += f' data-outcome="{html.escape(outcomes[idx])}"'
            mark = f' <span style="color:{color}">{sym}</span>'
        rows.append(
            f'<tr data-risk="{risk}"{attrs} title="{tip}">'
            f'<td style="padding:1px 4px;white-space:nowrap">{idx}{mark}</td>'
            f'<td style="padding:1px 4px"><b>{html.escape(macro_label(m))}</b></td>'
            f'<td style="{_WRAP}"><code>{html.escape(a)}</code> &rarr; '
            f"<code>{html.escape(b)}</code></td>"
            f'<td style="padding:1px 4px;white-space:nowrap"><span style="color:{RISK_COLORS[risk]};'
            f'font-weight:bold">{RISK_SYMBOLS[risk]}</span> {risk}</td></tr>'
        )
    name = html.escape(str(getattr(program, "name", "program")))
    n_risky = sum(macro_risk(m) == "risky" for m in macros)
    head = f"<b>Program {name}</b>: {len(macros)} macros, {n_risky} risky"
    table = (
        f'<table class="dlovr-program" data-program="{name}" '
        'style="border-collapse:collapse;font-size:11px;width:100%;'
        'table-layout:fixed"><colgroup><col style="width:26px"><col style="width:38px"><col>'
        '<col style="width:60px"></colgroup>'
        '<tr style="text-align:left"><th>#</th><th>class</th><th>principal change (from &rarr; to)</th>'
        f"<th>risk</th></tr>{''.join(rows)}</table>"
    )
    why = risk_reasons(program)
    key = ""
    if outcomes:
        key = '<div class="dlovr-outcome-key" style="margin-top:3px">' + ", ".join(
            f'<span style="color:{color}">{sym}</span> {meaning}'
            for sym, color, meaning in OUTCOME_MARKS.values()) + "</div>"
    risky = ""
    if why:
        items = "".join(f"<li>{html.escape(w)}</li>" for w in why)
        risky = (
            f'<div class="dlovr-risky" style="color:{RISK_COLORS["risky"]};margin-top:3px">'
            f"<b>Risky program:</b><ul style='margin:0;padding-left:14px'>{items}</ul></div>"
        )
    paths = "".join(
        f"<div>{html.escape(label)}: <code>{html.escape(str(p))}</code></div>" for label, p in files
    )
    body = f'{head}{table}{key}{risky}<div style="margin-top:3px">{paths}</div>'
    return f'<div style="font-size:11px">{body}</div>'
