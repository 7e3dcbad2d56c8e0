"""The current scene's transition network in the browser UI (no viser): where it comes
from, and the HTML (inline SVG of
:mod:`dlovr.recording.network_html`) with the live situation highlighted.

The network of a scene is the file ``<scene>.network.json`` (written by ``dlovr network``) in the
recordings directory or the repository's ``recordings/``, else it is built on demand from the
recordings of that scene found there (:func:`dlovr.recording.demonstrations.network_from_recordings`).
The live node is the node whose discrete situation is the contact tracker's current kept situation.
"""

from __future__ import annotations

from collections.abc import Sequence
from html import escape
from pathlib import Path

from dlovr.model.network import Network, NetworkError, load_network
from dlovr.recording import RecordingError
from dlovr.recording.network_html import CSS, network_svg
from dlovr.ui.page_js import on_drawn

LIVE_COLOR = "#1f77b4"
TEXT_PX = 20.0
"""The drawing's node text (px, before the scaling; edge text 0.9 of it): enlarged to stay readable
when the drawing is scaled down, the labels placed for that size (no two overlap)."""
FIT_CSS = f"""
#network {{ height: auto; max-width: none; }}
#network text {{ font-size: {TEXT_PX:g}px; }}
#network .nid {{ font-size: 17px; }}
#network .elabel {{ font-size: {0.9 * TEXT_PX:g}px; }}
"""

ZOOM = 0.5
"""The drawing's scale in the panel at first (its text 10 px high): a long network scrolls sideways
rather than being squeezed to the panel's width (peg-in-hole's 15 nodes were 16 px high)."""

_SVG = "this.closest('.dlovr-network').querySelector('svg')"
_ZOOM_JS = (
    "var s=" + _SVG + ";var z=(window.__dlovrNetZoom||" + str(ZOOM) + ")*{f};"
    "z=Math.min(3,Math.max(0.1,z));window.__dlovrNetZoom=z;"
    "s.style.width=(s.width.baseVal.value*z)+'px';"
)
_FULL_JS = (
    "var w=window.open('','dlovr-network');w.document.title='transition network';"
    "w.document.body.innerHTML=this.closest('.dlovr-network').querySelector('style').outerHTML+"
    + _SVG + ".outerHTML;w.document.querySelector('svg').style.width='';"
)


def scene_recordings(scene_name: str, folders: Sequence[Path]) -> list[Path]:
    """The recordings (``*.mcap``) in ``folders`` made in the scene named ``scene_name``, sorted by
    path, each once."""
    from dlovr.recording import Recording

    out: dict[Path, Path] = {}
    for folder in folders:
        if not folder.is_dir():
            continue
        for p in sorted(folder.glob("*.mcap")):
            try:
                if Recording(p).metadata.get("scene_name") == scene_name:
                    out.setdefault(p.resolve(), p)
            except (RecordingError, OSError):
                continue
    return sorted(out.values())


def scene_network(scene_name: str, folders: Sequence[Path]) -> tuple[Network | None, str]:
    """The network of the scene and where it came from (a one-line note), or None and why not."""
    for folder in folders:
        path = folder / f"{scene_name}.network.json"
        if path.is_file():
            try:
                return load_network(path), f"from {path}"
            except NetworkError as e:  # an InputError naming the file
                return None, f"cannot read {e}"
    recs = scene_recordings(scene_name, folders)
    if not recs:
        return None, f"no network and no recording of scene {scene_name}"
    from dlovr.model.program import ChatterRules
    from dlovr.recording.demonstrations import network_from_recordings

    try:  # as `dlovr network` builds it: the chatter of each recording a hand made removed
        net = network_from_recordings(recs, chatter=ChatterRules(), hands_only=True)
    except (NetworkError, RecordingError, ValueError) as e:
        return None, f"cannot build the network: {e}"
    n = len(recs)
    return net, f"built from {n} recording{'s' if n != 1 else ''} of scene {scene_name}"


def network_view_html(net: Network, live: str | None, situation: str = "", note: str = "") -> str:
    """The network's drawing with node ``live`` (an id, or None outside the network) ringed and
    filled in :data:`LIVE_COLOR`; ``data-live`` on the outer ``div`` names it (empty: none)."""
    ring = ""
    if live is not None:
        ring = (
            f'#network g.node[data-node="{live}"] circle:last-of-type '
            f"{{ stroke: {LIVE_COLOR}; stroke-width: 7px; }}\n"
            f'#network g.node[data-node="{live}"] .nid {{ fill: #fff; }}\n'
        )
    css = "\n".join(line for line in CSS.splitlines() if line.startswith("#network")) + "\n" + ring
    css += FIT_CSS
    where = f"live: <b>{live}</b>" if live is not None else "live: <b>outside the network</b>"
    if situation:
        where += f" <code>{escape(situation)}</code>"
    head = (
        f"{len(net.nodes)} situations, {len(net.edges)} transitions, start {net.start}, goal {net.goal}"
        f"{' (' + escape(note) + ')' if note else ''}<br>{where}"
    )
    svg = network_svg(net, text_px=TEXT_PX)
    sized = svg.replace("<svg ", f'<svg style="width:{ZOOM * _svg_width(svg):.0f}px" ', 1)
    # the zoom a person chose survives the redraws (the live node moves): applied as the image loads
    keep = _ZOOM_JS.format(f="1").replace(_SVG, "this.parentNode.querySelector('svg')")
    buttons = "".join(
        f'<button type="button" class="dlovr-net-{name}" title="{tip}" onclick="{js}" '
        f'style="font-size:11px;margin-right:3px">{label}</button>'
        for name, label, tip, js in (
            ("out", "&minus;", "zoom out", _ZOOM_JS.format(f="0.8")),
            ("in", "+", "zoom in", _ZOOM_JS.format(f="1.25")),
            ("full", "full size", "open the drawing at full size in a new window", _FULL_JS),
        )
    )
    return (
        f'<div class="dlovr-network" data-live="{live or ""}" style="font-size:11px">'
        f"<style>{css}</style>{head}<div>{buttons}</div>"
        f'<div class="dlovr-net-scroll" style="border:1px solid #ddd;overflow:auto;max-height:60vh">'
        f"{sized}"
        f"{on_drawn(keep)}</div></div>"
    )


def _svg_width(svg: str) -> float:
    """The width attribute (px) of the drawing's ``<svg>``."""
    head = svg[: svg.find(">")]
    i = head.find('width="')
    return float(head[i + 7 : head.index('"', i + 7)]) if i >= 0 else 800.0
