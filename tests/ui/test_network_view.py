"""The network view's helpers (no browser): where a scene's network comes from, and its HTML."""

from __future__ import annotations

from pathlib import Path

from dlovr.ui.network_view import network_view_html, scene_network, scene_recordings

ROOT = Path(__file__).resolve().parents[2]


def test_a_network_file_wins_over_building_from_the_recordings(tmp_path: Path):
    built, note = scene_network("table", [tmp_path, ROOT / "recordings"])
    assert built is not None and "built from 1 recording of scene table" in note
    assert scene_recordings("table", [ROOT / "recordings"]) == [ROOT / "recordings" / "table.mcap"]
    (tmp_path / "table.network.json").write_text(built.dumps())
    loaded, note = scene_network("table", [tmp_path, ROOT / "recordings"])
    assert loaded == built and note == f"from {tmp_path / 'table.network.json'}"
    (tmp_path / "table.network.json").write_text("{not json")
    bad, note = scene_network("table", [tmp_path])
    assert bad is None and note.startswith("cannot read")
    none, note = scene_network("nowhere", [tmp_path])
    assert none is None and "no recording of scene nowhere" in note


def test_the_live_node_is_ringed_and_named():
    net, _ = scene_network("table", [ROOT / "recordings"])
    assert net is not None
    page = network_view_html(net, net.start, "V/G & E/N & V/N")
    assert f'data-live="{net.start}"' in page and f'g.node[data-node="{net.start}"]' in page
    assert page.count("data-node=") == len(net.nodes) + 2  # the nodes and the two CSS rules
    outside = network_view_html(net, None, "V/G & E/F[x.F1] & V/N")
    assert 'data-live=""' in outside and "outside the network" in outside


def test_no_two_nodes_read_alike_and_no_two_labels_overlap():
    import re
    from html import unescape

    from dlovr.recording.network_html import _overlaps, _text_box, node_labels
    from dlovr.ui.network_view import TEXT_PX

    for scene in ("table", "peg_in_hole", "corners", "edges"):  # corners, edges: crowded
        net, _ = scene_network(scene, [ROOT / "recordings"])
        assert net is not None
        labels = node_labels(net)
        assert len({tuple(v) for v in labels.values()}) == len(net.nodes), labels  # table: n3, n4 alike
        page = network_view_html(net, None)
        pattern = r'<text class="(nlabel|role|elabel)" x="([-\d.]+)" y="([-\d.]+)">([^<]*)</text>'
        texts = re.findall(pattern, page)
        px = {"elabel": 0.9 * TEXT_PX, "nlabel": TEXT_PX, "role": TEXT_PX}
        boxes = [_text_box(float(x), float(y), unescape(t), px[c]) for c, x, y, t in texts]
        assert len(texts) >= len(net.nodes) + len(net.edges)
        pairs = [(i, j) for i in range(len(boxes)) for j in range(i)]
        clash = [(texts[i], texts[j]) for i, j in pairs if _overlaps(boxes[i], boxes[j])]
        assert not clash, (scene, clash[:3])
        circle = r'<circle cx="([-\d.]+)" cy="([-\d.]+)" r="([-\d.]+)" fill="#'
        nodes = [(float(x) - float(r), float(y) - float(r), float(x) + float(r), float(y) + float(r))
                 for x, y, r in re.findall(circle, page)]
        assert len(nodes) == len(net.nodes)
        on_node = [texts[i] for i, b in enumerate(boxes) if any(_overlaps(b, c) for c in nodes)]
        assert not on_node, (scene, on_node[:3])
