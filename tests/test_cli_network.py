"""`dlovr network` and `dlovr compile --network` on the sample recordings, and the HTML view
in headless Chromium (Debian's ``chromium``; skipped without it, as in tests/ui/test_ui.py)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from dlovr.cli import main
from dlovr.model.network import Network
from dlovr.model.planning import NetworkProgram
from dlovr.recording import compile_recording

SAMPLES = Path(__file__).parents[1] / "recordings"
PEG = SAMPLES / "peg_in_hole.mcap"


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def dlovr(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dlovr", *map(str, args)], capture_output=True, text=True)


@pytest.fixture(scope="module")
def three(tmp_path_factory) -> Path:
    """Three copies of the peg-in-hole sample recording in one directory."""
    d = tmp_path_factory.mktemp("demos")
    for k in range(3):
        shutil.copy(PEG, d / f"peg{k}.mcap")
    return d


@pytest.fixture(scope="module")
def built(three, tmp_path_factory) -> tuple[Path, Path]:
    out = tmp_path_factory.mktemp("net")
    r = cli("network", three, "-o", out / "net.json", "--html", out / "net.html")
    assert r.exit_code == 0, r.output
    assert "15 situations, 14 transitions (2 risky) from 3 recordings of peg_in_hole" in r.output
    return out / "net.json", out / "net.html"


def test_network_of_three_copies_counts_every_transition_three_times(built):
    net = json.loads(built[0].read_text())
    assert net["kind"] == "transition-network" and net["scene_name"] == "peg_in_hole"
    assert len(net["demonstrations"]) == 3
    assert {e["count"] for e in net["edges"]} == {3}
    nodes = {n["id"]: n for n in net["nodes"]}
    assert nodes[net["start"]]["situation"] == "V/G & E/N & V/N"
    assert nodes[net["goal"]]["situation"].endswith("V/VS[block.F5,holeblock.F1,holeblock.F6]")
    assert nodes[net["start"]]["visits"] == 3  # free space, once in each recording (the flight is not kept)
    free_out = [e for e in net["edges"] if e["source"] == net["start"]]
    assert [e["probability"] for e in free_out] == [1.0]
    # the flight off the corner is S,E, as in the program: the edge knows it passed through free space
    assert sorted(e["label"] for e in net["edges"] if e["risk"] == "risky") == ["I", "S,E"]


def _networks(tmp_path: Path, recordings: Path, *flags: str) -> dict[str, tuple[str, dict]]:
    """``dlovr network RECORDINGS [FLAG]`` for each flag ("": none): its output and its file."""
    out = {}
    for flag in flags:
        path = tmp_path / f"net{flag}.json"
        r = cli("network", recordings, *([flag] if flag else []), "-o", path)
        assert r.exit_code == 0, r.output
        out[flag] = (r.output, json.loads(path.read_text()))
    return out


def test_a_scripts_flips_stay_unless_without_chatter(tmp_path):
    """The sample table recording, played from its script, flips between two situations of the cable
    lying on the table (``-`` back and forth, three times each, within a moment): the scene's flips,
    not a hovering hand's, so `dlovr network` keeps them (as ``--keep-chatter`` does) and
    ``--without-chatter`` removes them (docs/networks.md)."""
    nets = _networks(tmp_path, SAMPLES / "table.mcap", "", "--keep-chatter", "--without-chatter")
    for flag in ("", "--keep-chatter"):
        assert "4 situations, 6 transitions (0 risky) from 1 recordings of table" in nets[flag][0]
        assert "chatter" not in nets[flag][1]
        back_and_forth = [e for e in nets[flag][1]["edges"] if e["label"] == "-"]
        assert len(back_and_forth) == 2 and {e["count"] for e in back_and_forth} == {3}
    output, removed = nets["--without-chatter"]
    assert "3 situations, 4 transitions (0 risky) from 1 recordings of table" in output
    assert removed["chatter"].startswith("removed from each demonstration (")
    assert all(e["label"] != "-" for e in removed["edges"])


@pytest.mark.slow
def test_network_drops_a_hands_chatter_by_default_and_keeps_it_on_request(tmp_path):
    """A person-like demonstration of the table script (`dlovr record --trials 1 --vary
    demo.person=1`, docs/people.md) flips as the script's does; made by a hand, its flips are
    chatter: `dlovr network` removes them and says so, ``--keep-chatter`` keeps them."""
    r = dlovr("record", "--script", Path(__file__).parents[1] / "scenes/table.script.toml", "--trials", 1,
              "--seed", 0, "--vary", "demo.person=1", "-o", tmp_path / "demos")
    assert r.returncode == 0, r.stderr
    nets = _networks(tmp_path, tmp_path / "demos", "", "--keep-chatter")
    output, dropped = nets[""]
    assert "3 situations, 4 transitions (0 risky) from 1 recordings of table" in output
    assert "removed from each demonstration made by a hand (1 of 1)" in dropped["chatter"]
    assert all(e["label"] != "-" for e in dropped["edges"])
    output, kept = nets["--keep-chatter"]
    assert "4 situations, 6 transitions (0 risky) from 1 recordings of table" in output
    assert "chatter" not in kept and any(e["label"] == "-" for e in kept["edges"])


@pytest.mark.slow
def test_network_without_chatter_merges_each_recordings_path_to_its_goal(three, tmp_path):
    """--without-chatter: each recording's chatter removed before merging, said so in the file; the
    scripted sample has none, so its network keeps its shape (docs/networks.md)."""
    r = cli("network", three / "peg0.mcap", "--without-chatter", "-o", tmp_path / "net.json")
    assert r.exit_code == 0, r.output
    assert "15 situations, 14 transitions (2 risky) from 1 recordings" in r.output
    net = json.loads((tmp_path / "net.json").read_text())
    assert "removed" in net["chatter"] and net["start"] != net["goal"]


def test_network_program_replays_the_demonstration_macro_for_macro(built, tmp_path):
    r = cli("compile", "--network", built[0], "-o", tmp_path / "prog.json")
    assert r.exit_code == 0, r.output
    assert "8 macros, 2 risky, P(goal)=1.000" in r.output
    prog = json.loads((tmp_path / "prog.json").read_text())
    assert prog["kind"] == "network-program" and prog["summary"]["plan_reach_probability"] == 1.0
    single = compile_recording(PEG)
    plan = prog["plan"]
    transitions = [m for m in single.macros if m.kind != "final"]
    # the same classes as the program's, the flight off the corner (S,E) included
    assert [tuple(c["macro"]["classes"]) for c in plan] == [m.classes for m in transitions]
    for c, m in zip(plan, transitions, strict=True):
        np.testing.assert_allclose(c["macro"]["world"], m.motion.world, atol=1e-8)
        assert [s["node"] for s in c["successors"]] == [c["macro"]["target"]]


def test_network_edges_carry_the_detections_derived_from_the_demonstrations(built, tmp_path):
    """Three copies of one recording: each classed edge's detection is the program's, parameter for
    parameter: the reference demonstration (the first) took every edge, so each is its own, marked so
    (an edge it did not take has the median over the demonstrations, test_network.py); the network
    program's macros carry them, so its detectors watch for the demonstrated steps, not the class
    defaults."""
    net = json.loads(built[0].read_text())
    single = compile_recording(PEG)
    by_target = {m.to_situation: m for m in single.macros if m.kind != "final"}
    nodes = {n["id"]: n["situation"] for n in net["nodes"]}
    classed = [e for e in net["edges"] if e["classes"]]
    assert len(classed) == len(by_target) == 8
    for e in classed:
        m = by_target[nodes[e["target"]]]
        assert [d["cls"] for d in e["detection"]] == list(m.classes)
        for d, want in zip(e["detection"], m.detection, strict=True):
            assert d["params"] == pytest.approx(want.params), e["label"]
            derived = [k for k, v in want.derivation.items() if v.startswith("derived")]
            merged = [d["derivation"][k] for k in derived]
            own = "(the reference demonstration's own: its macro follows its track)"
            assert merged and all(t.endswith(own) for t in merged)
    r = cli("compile", "--network", built[0], "-o", tmp_path / "prog.json")
    assert r.exit_code == 0, r.output
    plan = json.loads((tmp_path / "prog.json").read_text())["plan"]
    for ch, m in zip(plan, [m for m in single.macros if m.kind != "final"], strict=True):
        for d, want in zip(ch["macro"]["detection"], m.detection, strict=True):
            assert d["params"] == pytest.approx(want.params)


def test_network_nodes_carry_the_contact_vector_the_demonstrations_sensed(built):
    """Free space senses nothing; the tip on the block's top senses its contact vector (down); every
    sensed vector is unit or zero; successors are identified by it."""
    net = json.loads(built[0].read_text())
    nodes = {n["situation"]: n for n in net["nodes"]}
    assert nodes["V/G & E/N & V/N"]["sensed"] == [0.0, 0.0, 0.0]
    np.testing.assert_allclose(nodes["V/G & E/N & V/F[block.F1]"]["sensed"], [0.0, 0.0, -1.0], atol=0.3)
    for n in net["nodes"]:
        assert n["sensed"] is not None
        assert np.linalg.norm(n["sensed"]) == pytest.approx(1.0) or not any(n["sensed"])
    first = NetworkProgram(Network.from_json(net), 0.02).replan(net["start"], None)
    by_id = {n["id"]: n for n in net["nodes"]}
    vectors = [None if s.vector is None else list(s.vector) for s in first.successors]
    assert vectors == [by_id[s.node]["sensed"] for s in first.successors]


def test_recordings_of_different_scenes_are_refused_with_one_line(tmp_path):
    r = dlovr("network", PEG, SAMPLES / "table.mcap", "-o", tmp_path / "net.json")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "scene" in r.stderr and "peg_in_hole" in r.stderr and "table" in r.stderr
    assert not (tmp_path / "net.json").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["network", "missing.mcap", "-o", "n.json"], "cannot read"),
        (["network", "empty_dir", "-o", "n.json"], "no recordings found"),
        (["compile", "--network", "missing.json", "-o", "p.json"], "missing.json: no such network file"),
        (["compile", "--network", "bad.json", "-o", "p.json"], "not valid JSON"),
        (["compile", "--network", "other.json", "-o", "p.json"], "not a transition network"),
        (["compile", "--network", "bad.json"], "needs -o"),
        (["compile"], "--network NET.json"),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path, args, message):
    (tmp_path / "empty_dir").mkdir()
    (tmp_path / "bad.json").write_text("{")
    (tmp_path / "other.json").write_text('{"version": 1}')
    r = subprocess.run(
        [sys.executable, "-m", "dlovr", *args], capture_output=True, text=True, cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])},
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and message in r.stderr, r.stderr


def test_html_view_is_self_contained(built):
    html = built[1].read_text()
    assert html.startswith("<!DOCTYPE html>") and "<svg" in html
    assert "http://" not in html.replace('xmlns="http://www.w3.org/2000/svg"', "")
    assert "https://" not in html and "<script" not in html and "<link" not in html
    assert html.count('class="node ') == 15 and html.count('class="edge risk-risky"') == 2
    assert "V/VS[block.F5,holeblock.F1,holeblock.F6]" in html and 'id="legend"' in html


def _chromium() -> str:
    path = shutil.which("chromium") or ("/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None)
    if path is None:
        msg = "chromium not found: `sudo apt-get install -y chromium` to run the browser tests"
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)
    return path


@pytest.mark.slow
def test_html_view_loads_in_headless_chromium_without_errors(built):
    exe = _chromium()
    from playwright.sync_api import sync_playwright

    from dlovr.ui.server import HEADLESS_CHROMIUM_ARGS

    errors: list[str] = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=exe, args=HEADLESS_CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 800})
            page.on("console", lambda m: errors.append(m.text) if m.type in ("error", "warning") else None)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.on("requestfailed", lambda r: errors.append(f"request failed: {r.url}"))
            page.goto(built[1].as_uri())
            page.wait_for_load_state("load")
            assert page.locator("#network g.node").count() == 15
            assert page.locator("#network g.edge").count() == 14
            box = page.locator("#network").bounding_box()
            assert box is not None and box["width"] > 1000 and box["height"] > 100  # one row: a chain
            dashed = page.locator("#network g.edge.risk-risky path[stroke-dasharray]")
            assert dashed.count() == 2
            assert page.locator("#network g.node title").first.text_content().startswith("n1 (start)")
        finally:
            browser.close()
    assert errors == []
