"""No contact is dropped (docs/model.md, the end-vertex rule): every MuJoCo contact on the cable with
a normal force appears in the step's contact situation, over the built-in scripts.

Each built-in script (scenes/*.script.toml) is simulated once, with the contact tracker, and every
step is checked: each raw MuJoCo contact on the cable whose normal force exceeds 0.02 N must appear in
the situation, as a contact that touches the same object at the contact's cable point or a
neighbouring one (a segment's contact: at either end of the segment or next to it). A tip touching a
face at a shallow angle (at the tip angle or less) is an ``E`` contact of the last segment, at the last
interior point; dropping it fails here (the edges, peg-in-hole and table scripts all do that).

Every step of every script is checked (about 74,000 steps, near a minute).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dlovr.scene import load_scene
from dlovr.script import load_script
from dlovr.sim import Simulator

SCENES = Path(__file__).resolve().parents[2] / "scenes"
SCRIPTS = sorted(SCENES.glob("*.script.toml"))
FORCE_N = 0.02
"""Contacts with a normal force above this (N) must appear in the situation."""


@pytest.fixture(autouse=True)
def _no_log_in_repo(tmp_path, monkeypatch) -> None:
    """MuJoCo writes its instability warnings to MUJOCO_LOG.TXT in the working directory."""
    monkeypatch.chdir(tmp_path)


def missing_contacts(script_path: Path) -> tuple[int, list[str]]:
    """Steps checked, and a description of every forceful raw contact missing from its situation."""
    script = load_script(script_path)
    sim = Simulator(load_scene(script.scene or "table"), track=True)
    missing: list[str] = []
    steps = 0
    for rec in sim.run(script):
        steps += 1
        arrays = rec.contact_arrays
        if arrays is None or not len(arrays.dist):
            continue
        force = np.asarray(arrays.force)
        strong = np.nonzero(force > FORCE_N)[0]
        if not len(strong):
            continue
        situation = sim.tracker.current.topological
        point_of = np.asarray(arrays.point)  # the cable point where MuJoCo reports a vertex
        segment = np.asarray(arrays.segment)
        for i in strong.tolist():
            obj = arrays.names[0][int(arrays.obj[i])]
            first = int(segment[i]) if segment[i] >= 0 else int(point_of[i])
            last = int(segment[i]) + 1 if segment[i] >= 0 else int(point_of[i])
            lo, hi = first - 1, last + 1
            if not any(
                c.dlo.span is not None and c.dlo.span[0] <= hi and c.dlo.span[1] >= lo and obj in c.objects
                for c in situation.contacts
            ):
                missing.append(
                    f"t={rec.time:.3f} s: {obj} at points {first}..{last} ({force[i]:.3f} N) "
                    f"not in {situation}"
                )
    return steps, missing


@pytest.mark.slow
@pytest.mark.parametrize("path", SCRIPTS, ids=[p.name.removesuffix(".script.toml") for p in SCRIPTS])
def test_every_forceful_contact_appears_in_the_situation(path):
    steps, missing = missing_contacts(path)
    assert steps > 1000
    assert not missing, f"{len(missing)} contacts missing, e.g. " + "; ".join(missing[:3])
