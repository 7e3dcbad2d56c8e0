"""The V-groove scenes of tests/sim/test_v_grooves.py and benchmarks/bench_jams.py: a block with one
V groove of a given opening and a script that presses a short cable into it (written into a folder)."""

from __future__ import annotations

import math
from pathlib import Path

from dlovr.geometry import prism_mesh

HALF_WIDTH, BOTTOM = 0.06, 0.02
"""The groove block: 12 cm wide, its groove line along y at x = 0 and z = 2 cm."""


def v_groove(tmp: Path, opening_deg: float, young: float, x0: float, press: float, hold: float,
             pose: str = "across") -> Path:
    """Write a scene with one V-groove block of the given opening angle (the angle between the two
    flanks, degrees) and a script that moves a 12 cm cable until it is ``press`` (m) deeper than
    touching, then holds ``hold`` s. Across (default): the cable horizontal, held at ``x0`` (m) and
    pointing along +x across the groove, lowered until its held end is ``press`` into the flank below
    it. ``down``: hanging, held above ``x0``, pushed tip first into the V until the tip is ``press``
    below where it would touch both flanks. ``along``: horizontal along the groove line (+y), held
    at y = ``x0``, pushed into the V until its held end is ``press`` below touching both flanks.
    Returns the script's path."""
    half = math.radians(opening_deg / 2)
    w, bottom = HALF_WIDTH, BOTTOM
    top = bottom + w / math.tan(half)
    prism_mesh([(-w, 0.0), (w, 0.0), (w, top), (0.0, bottom), (-w, top)], 0.2).export(tmp / "v.obj")
    quat = {"across": "[0.7071068, 0.0, -0.7071068, 0.0]", "down": "[1.0, 0.0, 0.0, 0.0]",
            "along": "[0.7071068, 0.7071068, 0.0, 0.0]"}[pose]
    x, y = (0.0, x0) if pose == "along" else (x0, 0.0)
    (tmp / "v.toml").write_text(
        f'name = "v"\n[dlo]\nlength = 0.12\nradius = 0.005\nsegments = 12\nyoung = {young:g}\nmass = 0.02\n'
        f"[gripper]\npos = [{x}, {y}, {top + 0.15:.5f}]\nquat = {quat}\n"
        '[[objects]]\nname = "v"\nmesh = "v.obj"\n'
    )
    if pose == "down":  # the tip's centre where it touches both flanks, plus the cable's length
        z = bottom + 0.005 / math.sin(half) + 0.12 - press
    elif pose == "along":  # the cable's centre where it touches both flanks
        z = bottom + 0.005 / math.sin(half) - press
    else:  # the cable's centre one radius above the flank under the held end
        z = bottom + abs(x0) / math.tan(half) + 0.005 / math.sin(half) - press
    script = tmp / "v.script.toml"
    script.write_text(
        'scene = "v.toml"\n'
        f"[[waypoints]]\npos = [{x}, {y}, {z + 0.02:.5f}]\nduration = 0.3\n"
        f"[[waypoints]]\npos = [{x}, {y}, {z:.5f}]\nduration = 0.6\nhold = {hold}\n"
    )
    return script
