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


def _svg(net: Network, plan_edges: set[str]) -> str:
    pos = layout(net)
    top = min(y for _, y in pos.values()) - 50.0

    def back(e: Edge) -> bool:
        return pos[e.source][0] - pos[e.target][0] > 1.5 * DX

    curves = {e.id: _edge_path(pos[e.source], pos[e.target], top if back(e) else None) for e in net.edges}
    xs = [x for x, _ in pos.values()] + [m[0] for _, m in curves.values()]
    ys = [y for _, y in pos.values()] + [m[1] for _, m in curves.values()]
    x0, y0 = min(min(xs) - MARGIN, 0.0), min(min(ys) - 40.0, 0.0)
    width, height = max(xs) + MARGIN + 120 - x0, max(ys) + 60 - y0
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
        d, (mx, my) = curves[e.id]
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
        out.append(
            f'<text class="elabel" x="{mx:.1f}" y="{my - 4:.1f}">{escape(e.label)} ×{e.count} · '
            f"{e.probability:.2f}</text></g>"
        )
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
        out.append(f'<text class="nid" x="{x:.1f}" y="{y + 4:.1f}">{n.id}</text>')
        lines = list(n.principal) or ["free"]
        above = round((x - MARGIN) / DX) % 2 == 1  # labels of odd layers above: neighbours do not overlap
        ty0 = y - R - 8 - 12 * (len(lines) - 1) if above else y + R + 14
        for k, line in enumerate(lines):
            out.append(f'<text class="nlabel" x="{x:.1f}" y="{ty0 + 12 * k:.1f}">{escape(line)}</text>')
        role = "start" if n.id == net.start else "goal" if n.id == net.goal else ""
        if role:
            ry = ty0 - 14 if above else y - R - 9
            out.append(f'<text class="role" x="{x:.1f}" y="{ry:.1f}">{role}</text>')
        out.append("</g>")
    out.append("</svg>")
    return "\n".join(out)


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
#network .elabel { fill: #333; font-size: 10px; }
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


def network_svg(net: Network, plan_edges: set[str] | None = None) -> str:
    """The drawing alone (inline SVG, ``id="network"``; style it with :data:`CSS`): one
    ``g.node[data-node]`` per node, one ``g.edge[data-edge]`` per edge (used by the browser UI)."""
    return _svg(net, set(plan_edges or ()))
