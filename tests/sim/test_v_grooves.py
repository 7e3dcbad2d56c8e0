"""A cable in V grooves built in the test, recorded with ``dlovr record``: the gripped end's contact
(docs/model.md, section 2) in a 120° groove."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from dlovr.cli import main
from dlovr.geometry import prism_mesh
from dlovr.recording import Recording, kept_states

HALF_WIDTH, TOP = 0.06, 0.05
"""The groove block: 12 cm wide, its flanks' top edges at z = 5 cm, its groove line along y at x = 0."""


def v_groove(tmp: Path, opening_deg: float, young: float, x0: float, press: float, hold: float) -> Path:
    """Write a scene with one V-groove block of the given opening angle (the angle between the two
    flanks, degrees) and a script that lowers a horizontal 12 cm cable, held at ``x0`` (m) and pointing
    along +x across the groove, until its held end is ``press`` (m) deeper than touching the flank
    below it, then holds ``hold`` s. Returns the script's path."""
    half = math.radians(opening_deg / 2)
    bottom = TOP - HALF_WIDTH / math.tan(half)
    w = HALF_WIDTH
    prism_mesh([(-w, 0.0), (w, 0.0), (w, TOP), (0.0, bottom), (-w, TOP)], 0.2).export(tmp / "v.obj")
    (tmp / "v.toml").write_text(
        f'name = "v"\n[dlo]\nlength = 0.12\nradius = 0.005\nsegments = 12\nyoung = {young:g}\nmass = 0.02\n'
        f"[gripper]\npos = [{x0}, 0.0, 0.15]\nquat = [0.7071068, 0.0, -0.7071068, 0.0]\n"
        '[[objects]]\nname = "v"\nmesh = "v.obj"\n'
    )
    flank = bottom + abs(x0) / math.tan(half)  # the flank's height under the held end
    z = flank + 0.005 / math.sin(half) - press  # the cable's centre one radius above the flank, less press
    script = tmp / "v.script.toml"
    script.write_text(
        'scene = "v.toml"\n'
        f"[[waypoints]]\npos = [{x0}, 0.0, {z + 0.02:.5f}]\nduration = 0.3\n"
        f"[[waypoints]]\npos = [{x0}, 0.0, {z:.5f}]\nduration = 0.6\nhold = {hold}\n"
    )
    return script


def record(script: Path, out: Path) -> Path:
    r = CliRunner().invoke(main, ["record", "--script", str(script), "-o", str(out)])
    assert r.exit_code == 0, r.output
    return out


@pytest.fixture(scope="module")
def held_across_120(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("v120")
    return record(v_groove(tmp, 120.0, 1e8, -0.045, 0.001, 0.3), tmp / "v120.mcap")


def test_the_gripped_ends_contact_is_a_contact_of_the_first_segment(held_across_120):
    """A cable held across a 120° V groove, its held end pressed into the near flank: V_S is V/G, and
    what it touches is an E contact at E_1 that carries the largest force (issue 27, item 4); the far
    flank's edge where the cable rests is a contact of its own."""
    rec = Recording(held_across_120)
    last = kept_states(rec)[-1]
    first = last.situation.contacts[1]
    assert last.situation.contacts[0].state.name == "V/G"
    assert first.state.name == "E/F" and first.span == (1, 1), last.situation.format()
    assert len(last.situation.successional()) == 2, last.situation.format()  # and the far flank
    payload = rec.states()[-1]
    forces = [c["force"] for c in payload["contacts"]]
    assert payload["contacts"][1]["state"] == "E/F" and forces[1] == max(forces) > 1.0, payload
    assert payload["topological"].startswith("VS/G & E1/v.F")
