"""A transition network as a self-contained HTML page (``dlovr network --html``): inline SVG and CSS,
no script and nothing fetched, so it opens offline in any browser.

Nodes are laid out in layers by their distance (in transitions) from the start node and coloured by the
stability of their least stable principal contact; edges are as wide as their probability, risky ones
(``I``, ``S``) red and dashed, cautious ones (``T``) orange and dotted; the planned path from the start
(when a network program is given) is underlaid in blue. Every node and edge has a hover title with its
details, and tables below the drawing list them all.
"""

from __future__ import annotations

import math
from html import escape

import networkx as nx

from dlovr.model.network import Edge, Network, Node
from dlovr.model.planning import NetworkProgram

STABILITY_COLORS = {"stable": "#2ca02c", "semi-stable": "#ff9f1c", "instable": "#d62728", "free": "#b8b8b8"}
RISK_STYLE = {  # stroke colour, dash pattern
    "none": ("#555555", ""),
    "caution": ("#e67e00", "2 4"),
    "risky": ("#d62728", "7 4"),
}
PLAN_COLOR = "#1f77b4"
DX, DY, R, MARGIN = 230.0, 120.0, 16.0, 70.0


def layout(net: Network) -> dict[str, tuple[float, float]]:
    """Node positions (px): layer = shortest distance from the start node (unreached nodes after the
    last layer), nodes of a layer in id order, each layer centred vertically."""
    g = net.graph()
    dist = nx.single_source_shortest_path_length(g, net.start)
    last = max(dist.values(), default=0)
    layers: dict[int, list[str]] = {}
    for n in net.nodes:
        layers.setdefault(dist.get(n.id, last + 1), []).append(n.id)
    tallest = max(len(v) for v in layers.values())
    pos = {}
    for layer, ids in layers.items():
        top = MARGIN + (tallest - len(ids)) * DY / 2
        for k, nid in enumerate(ids):
            pos[nid] = (MARGIN + layer * DX, top + k * DY)
    return pos


def _edge_path(
    a: tuple[float, float], b: tuple[float, float], over: float | None = None
) -> tuple[str, tuple[float, float]]:
    """A quadratic curve from circle ``a`` to circle ``b`` bent to the right of its direction (so the
    two directions of a pair do not overlap), or arched up to height ``over`` (a long edge back to an
    earlier layer, kept clear of the nodes between), and the point at its middle."""
    (x0, y0), (x1, y1) = a, b
    dx, dy = x1 - x0, y1 - y0
    d = math.hypot(dx, dy) or 1.0
    ux, uy = dx / d, dy / d
    bend = 10.0 + 0.18 * min(d, 400.0)
    cx, cy = (x0 + x1) / 2 - uy * bend, (y0 + y1) / 2 + ux * bend
    if over is not None:  # a cubic: up from a, across at height ``over``, down into b
        cy = (over - (y0 + y1) / 8) / 0.75
        sx, sy = _towards((x0, y0), (x0, cy), R)
        ex, ey = _towards((x1, y1), (x1, cy), R + 3.0)
        d = f"M{sx:.1f},{sy:.1f} C{x0:.1f},{cy:.1f} {x1:.1f},{cy:.1f} {ex:.1f},{ey:.1f}"
        return d, ((x0 + x1) / 2, over)
    sx, sy = _towards((x0, y0), (cx, cy), R)
    ex, ey = _towards((x1, y1), (cx, cy), R + 3.0)
    mx, my = 0.25 * sx + 0.5 * cx + 0.25 * ex, 0.25 * sy + 0.5 * cy + 0.25 * ey
    return f"M{sx:.1f},{sy:.1f} Q{cx:.1f},{cy:.1f} {ex:.1f},{ey:.1f}", (mx, my)


def _towards(p: tuple[float, float], q: tuple[float, float], r: float) -> tuple[float, float]:
    dx, dy = q[0] - p[0], q[1] - p[1]
    d = math.hypot(dx, dy) or 1.0
    return p[0] + dx / d * r, p[1] + dy / d * r


def _node_title(n: Node, net: Network) -> str:
    vec = "unknown" if n.vector is None else "(" + ", ".join(f"{x:+.3f}" for x in n.vector) + ")"
    role = " (start)" if n.id == net.start else " (goal)" if n.id == net.goal else ""
    return (
        f"{n.id}{role}: {n.situation}\nstability: {n.stability}"
        f"\nprincipal: {', '.join(n.principal) or 'none'}"
        f"\ncontact vector: {vec}\nvisits: {n.visits}, held {n.total_time:.3f} s in all, "
        f"{n.mean_time:.3f} s on average"
    )


def _edge_title(e: Edge) -> str:
    m = e.motion
    mean = ", ".join(f"{x:+.4f}" for x in m.world_mean)
    std = ", ".join(f"{x:.4f}" for x in m.world_std)
    dur = sum(e.durations) / len(e.durations)
    return (
        f"{e.id}: class {e.label}, risk {e.risk}\ncount {e.count}, probability {e.probability:.3f}"
        f"\nduration {dur:.3f} s on average\ngripper motion (world, m): ({mean}) ± ({std})"
    )


Box = tuple[float, float, float, float]
"""A text's box on the drawing (px): left, top, right, bottom."""

CHAR_W = 0.6
"""A character's width as a fraction of the font size (an estimate for placing the labels)."""

WRAP = 24
"""The longest line of a node's label (characters); a longer contact is broken after a comma."""


def _overlaps(a: Box, b: Box) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _wrap(text: str, width: int = WRAP) -> list[str]:
    """``text`` in lines of at most ``width`` characters, broken after commas and ``&`` (a longer
    piece whole)."""
    lines, line = [], ""
    for piece in text.replace(",", ",\0").replace("&", "&\0").split("\0"):
        if line and len(line) + len(piece) > width:
            lines.append(line)
            line = ""
        line += piece
    return [*lines, line]


def _shape(situation: str) -> str:
    """A situation without its face names (``V/G&E/N&E/F&V/N``): what tells apart two nodes whose
    principal contacts read alike."""
    parts = [part.split("[")[0].strip() for part in situation.split("&")]
    return "&".join(parts)


def _differing(situation: str, others: list[str]) -> str:
    """The contacts of ``situation`` that differ from those at the same place in ``others`` (all of
    them when the counts differ), joined by ``&``."""
    parts = [x.strip() for x in situation.split("&")]
    split = [[x.strip() for x in o.split("&")] for o in others]
    if any(len(o) != len(parts) for o in split):
        return situation
    return " & ".join(x for k, x in enumerate(parts) if any(o[k] != x for o in split))


def node_labels(net: Network) -> dict[str, list[str]]:
    """Each node's label lines: its principal contacts (``free`` when none), wrapped; nodes whose
    lines would read alike get their situation's shape (:func:`_shape`) added, and the contacts where
    their situations differ when that is alike too, so that no two nodes carry the same label."""
    lines = {n.id: [x for c in (n.principal or ("free",)) for x in _wrap(c)] for n in net.nodes}
    sit = {n.id: n.situation for n in net.nodes}
    for extra in (
        lambda nid, ids: _wrap(_shape(sit[nid])),
        lambda nid, ids: _wrap(_differing(sit[nid], [sit[i] for i in ids if i != nid])),
    ):
        seen: dict[tuple[str, ...], list[str]] = {}
        for n in net.nodes:
            seen.setdefault(tuple(lines[n.id]), []).append(n.id)
        for ids in seen.values():
            if len(ids) > 1:
                for nid in ids:
                    lines[nid] = lines[nid] + extra(nid, ids)
    return lines


def _text_box(x: float, baseline: float, text: str, px: float) -> Box:
    w = CHAR_W * px * len(text) + 4.0  # with a little room around
    return (x - w / 2, baseline - 0.85 * px, x + w / 2, baseline + 0.3 * px)


def _place(candidates: list[list[Box]], taken: list[Box]) -> int:
    """The first candidate (a set of boxes) that overlaps none of ``taken``, else the one that overlaps
    the fewest."""
    counts: list[int] = []
    for cand in candidates:
        count = sum(_overlaps(b, t) for b in cand for t in taken)
        if count == 0:
            return len(counts)
        counts.append(count)
    return counts.index(min(counts))


def _svg(net: Network, plan_edges: set[str], text_px: float = 11.0) -> str:
    pos = layout(net)
    top = min(y for _, y in pos.values()) - 50.0

    def back(e: Edge) -> bool:
        return pos[e.source][0] - pos[e.target][0] > 1.5 * DX

    curves = {e.id: _edge_path(pos[e.source], pos[e.target], top if back(e) else None) for e in net.edges}
    taken: list[Box] = [(x - R - 3, y - R - 3, x + R + 3, y + R + 3) for x, y in pos.values()]
    nodes = _node_texts(net, pos, text_px, taken)
    edges = _edge_texts(net, curves, 0.9 * text_px, taken)
    x0 = min(min(b[0] for b in taken) - 20.0, 0.0)
    y0 = min(min(b[1] for b in taken) - 20.0, 0.0)
    width = max(max(b[2] for b in taken), max(x for x, _ in pos.values()) + MARGIN) + 20.0 - x0
    height = max(b[3] for b in taken) + 20.0 - y0
    out = [
        f'<svg id="network" xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height:.0f}" '
        f'viewBox="{x0:.0f} {y0:.0f} {width:.0f} {height:.0f}" role="img" aria-label="transition network">',
        "<defs>",
    ]
    for risk, (color, _) in RISK_STYLE.items():
        out.append(
            f'<marker id="arrow-{risk}" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="13" '
            f'markerHeight="13" markerUnits="userSpaceOnUse" orient="auto-start-reverse">'
            f'<path d="M0,0 L10,5 L0,10 z" fill="{color}"/></marker>'
        )
    out.append("</defs>")
    for e in net.edges:
        d = curves[e.id][0]
        color, dash = RISK_STYLE[e.risk]
        width_px = 1.2 + 6.0 * e.probability
        out.append(f'<g class="edge risk-{e.risk}" data-edge="{escape(e.id)}">')
        out.append(f"<title>{escape(_edge_title(e))}</title>")
        if e.id in plan_edges:
            out.append(
                f'<path class="plan" d="{d}" fill="none" stroke="{PLAN_COLOR}" stroke-opacity="0.3" '
                f'stroke-width="{width_px + 9:.1f}" stroke-linecap="round"/>'
            )
        dash_attr = f' stroke-dasharray="{dash}"' if dash else ""
        out.append(
            f'<path d="{d}" fill="none" stroke="{color}" stroke-width="{width_px:.1f}"{dash_attr} '
            f'marker-end="url(#arrow-{e.risk})"/>'
        )
        out.append(f"{edges[e.id]}</g>")
    for n in net.nodes:
        x, y = pos[n.id]
        fill = STABILITY_COLORS[n.stability]
        out.append(f'<g class="node stability-{n.stability}" data-node="{n.id}">')
        out.append(f"<title>{escape(_node_title(n, net))}</title>")
        if n.id == net.goal:
            out.append(
                f'<circle cx="{x:.1f}" cy="{y:.1f}" r="{R + 5:.1f}" fill="none" stroke="#000" '
                'stroke-width="2"/>'
            )
        stroke = 4 if n.id == net.start else 1.5
        out.append(
            f'<circle cx="{x:.1f}" cy="{y:.1f}" r="{R:.1f}" fill="{fill}" stroke="#000" '
            f'stroke-width="{stroke}"/>'
        )
        out.append(f'<text class="nid" x="{x:.1f}" y="{y + 4:.1f}">{n.id}</text>{nodes[n.id]}</g>')
    out.append("</svg>")
    return "\n".join(out)


def _node_texts(net: Network, pos: dict[str, tuple[float, float]], px: float, taken: list[Box]) -> dict[
    str, str
]:
    """Each node's label (and its role, start or goal, above it) as SVG text, placed below or above
    its circle (above on odd layers, so that neighbours alternate) where it overlaps nothing placed
    before (``taken``: boxes, extended with the labels placed)."""
    labels = node_labels(net)
    lh = 1.15 * px
    out = {}
    for n in net.nodes:
        x, y = pos[n.id]
        role = "start" if n.id == net.start else "goal" if n.id == net.goal else ""
        lines = [("role", role)] * bool(role) + [("nlabel", t) for t in labels[n.id]]
        below = [y + R + 6 + 0.8 * px + k * lh for k in range(len(lines))]
        above = [b - (below[-1] - below[0]) - 2 * R - 12 - 0.8 * px - 0.25 * px for b in below]
        ys = [above, below] if round((x - MARGIN) / DX) % 2 == 1 else [below, above]
        sides = [(x, side) for side in ys]
        half = CHAR_W * px * max(len(t) for _, t in lines) / 2 + R + 6  # beside the circle, at mid-height
        mid = [y + 0.3 * px + (k - (len(lines) - 1) / 2) * lh for k in range(len(lines))]
        sides += [(x + half, mid), (x - half, mid)]
        # a crowded network: further below or above, then further aside
        sides += [(x, [b + s * k * lh for b in ys[i]]) for k in range(1, 9) for i, s in ((0, 1), (1, -1))]
        sides += [(x + s * k * half, mid) for k in (2, 3) for s in (1.0, -1.0)]
        boxes = [[_text_box(sx, b, t, px) for b, (_, t) in zip(ys_, lines, strict=True)] for sx, ys_ in sides]
        k = _place(boxes, taken)
        taken.extend(boxes[k])
        sx = sides[k][0]
        out[n.id] = "".join(
            f'<text class="{cls}" x="{sx:.1f}" y="{b:.1f}">{escape(t)}</text>'
            for b, (cls, t) in zip(sides[k][1], lines, strict=True)
        )
    return out


def _edge_texts(
    net: Network, curves: dict[str, tuple[str, tuple[float, float]]], px: float, taken: list[Box]
) -> dict[str, str]:
    """Each edge's label (class ×count · probability) as SVG text at the middle of its curve, moved
    up or down (by up to 14 lines), or aside, to overlap no circle and no label placed before."""
    out = {}
    for e in net.edges:
        mx, my = curves[e.id][1]
        text = f"{e.label} ×{e.count} · {e.probability:.2f}"
        w = CHAR_W * px * len(text)
        shifts = [(0.0, 0.0)] + [(0.0, s * k * 1.1 * px) for k in range(1, 7) for s in (-1.0, 1.0)]
        shifts += [(s * 0.6 * w, dy) for dy in (0.0, -1.1 * px, 1.1 * px) for s in (-1.0, 1.0)]
        # a crowded network: further up or down, and aside at every height
        shifts += [(0.0, s * k * 1.1 * px) for k in range(7, 15) for s in (-1.0, 1.0)]
        shifts += [(s * f * w, k * 1.1 * px) for k in range(-6, 7) for f in (0.6, 1.2) for s in (-1.0, 1.0)]
        boxes = [[_text_box(mx + dx, my - 4 + dy, text, px)] for dx, dy in shifts]
        k = _place(boxes, taken)
        taken.extend(boxes[k])
        x, y = mx + shifts[k][0], my - 4 + shifts[k][1]
        out[e.id] = f'<text class="elabel" x="{x:.1f}" y="{y:.1f}">{escape(text)}</text>'
    return out


def _legend() -> str:
    items = [
        f'<span class="sw" style="background:{c}"></span>{escape(k)}' for k, c in STABILITY_COLORS.items()
    ]
    rows = [
        "<b>Nodes</b> (stability of the least stable principal contact): " + " ".join(items),
        "thick ring: start; double ring: goal; label: principal contacts with face names",
        "<b>Edges</b>: width = probability of leaving the node along it; label: class ×count · probability",
    ]
    for risk, (color, dash) in RISK_STYLE.items():
        dash_attr = f' stroke-dasharray="{dash}"' if dash else ""
        why = {"none": "C, E, - (stable)", "caution": "T (semi-stable)", "risky": "I, S (instable)"}[risk]
        rows.append(
            f'<svg width="46" height="10"><line x1="2" y1="5" x2="44" y2="5" stroke="{color}" '
            f'stroke-width="3"{dash_attr}/></svg> risk {risk}: {why}'
        )
    rows.append(
        f'<svg width="46" height="12"><line x1="2" y1="6" x2="44" y2="6" stroke="{PLAN_COLOR}" '
        'stroke-opacity="0.3" stroke-width="10"/></svg> planned path from the start (network program)'
    )
    return '<div id="legend">' + "".join(f"<div>{r}</div>" for r in rows) + "</div>"


def _tables(net: Network) -> str:
    nodes = "".join(
        f"<tr><td>{n.id}</td><td>{escape(n.stability)}</td><td>{n.visits}</td><td>{n.mean_time:.3f}</td>"
        f"<td><code>{escape(n.situation)}</code></td></tr>"
        for n in net.nodes
    )
    edges = "".join(
        f"<tr><td>{escape(e.id)}</td><td>{escape(e.label)}</td><td>{e.risk}</td><td>{e.count}</td>"
        f"<td>{e.probability:.3f}</td><td>{sum(e.durations) / len(e.durations):.3f}</td>"
        f"<td>{', '.join(f'{x:+.4f}' for x in e.motion.world_mean)}</td></tr>"
        for e in net.edges
    )
    return (
        "<h2>Nodes</h2><table><tr><th>id</th><th>stability</th><th>visits</th><th>mean held [s]</th>"
        f"<th>situation</th></tr>{nodes}</table>"
        "<h2>Edges</h2><table><tr><th>edge</th><th>class</th><th>risk</th><th>count</th>"
        "<th>probability</th><th>mean duration [s]</th><th>mean motion, world [m]</th></tr>"
        f"{edges}</table>"
    )


CSS = """
body { font-family: sans-serif; margin: 1em; color: #222; }
#network text { font-size: 11px; text-anchor: middle; }
#network .nid { font-size: 10px; font-weight: bold; }
#network .role { font-weight: bold; }
#network .elabel { fill: #333; font-size: 10px; paint-order: stroke; stroke: #fff; stroke-width: 3px; }
#network g.edge:hover path { stroke-opacity: 0.6; }
#network g.node:hover circle { stroke: #1f77b4; }
#legend { margin: 0.5em 0; line-height: 1.7; }
#legend .sw { display: inline-block; width: 12px; height: 12px; border: 1px solid #000;
  margin: 0 4px 0 10px; vertical-align: middle; }
table { border-collapse: collapse; font-size: 12px; margin-bottom: 1em; }
td, th { border: 1px solid #ccc; padding: 2px 6px; text-align: left; }
.scroll { overflow: auto; border: 1px solid #ddd; }
"""


def network_html(net: Network, program: NetworkProgram | None = None, title: str = "") -> str:
    """The page for ``net`` (module docstring); ``program`` adds its planned path from the start."""
    plan_edges: set[str] = set()
    if program is not None:
        for ch in program.plan_from_start():
            plan_edges.update(ch.macro.edges)
    title = title or f"Transition network: {net.scene_name}"
    summary = (
        f"{len(net.demonstrations)} demonstrations of scene <b>{escape(net.scene_name)}</b>, "
        f"{len(net.nodes)} situations, {len(net.edges)} transitions; start {net.start}, goal {net.goal}."
    )
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{escape(title)}</title><style>{CSS}</style></head><body>"
        f"<h1>{escape(title)}</h1><p>{summary}</p>{_legend()}"
        f'<div class="scroll">{_svg(net, plan_edges)}</div>{_tables(net)}</body></html>\n'
    )


def network_svg(net: Network, plan_edges: set[str] | None = None, text_px: float = 11.0) -> str:
    """The drawing alone (inline SVG, ``id="network"``; style it with :data:`CSS`): one
    ``g.node[data-node]`` per node, one ``g.edge[data-edge]`` per edge (used by the browser UI).
    The labels are placed for node text ``text_px`` high and edge text 0.9 of that (the browser UI
    draws the drawing scaled down, its text larger)."""
    return _svg(net, set(plan_edges or ()), text_px)
