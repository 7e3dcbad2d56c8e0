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

LIVE_COLOR = "#1f77b4"
FIT_CSS = """
#network { width: 100%; height: auto; }
#network text { font-size: 20px; }
#network .nid, #network .elabel { font-size: 17px; }
"""
"""The drawing fits the panel's width (scaled down), its text enlarged to stay readable."""


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
    from dlovr.recording.demonstrations import network_from_recordings

    try:
        net = network_from_recordings(recs)
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
    return (
        f'<div class="dlovr-network" data-live="{live or ""}" style="font-size:11px">'
        f"<style>{css}</style>{head}"
        f'<div style="border:1px solid #ddd">{network_svg(net)}</div></div>'
    )
