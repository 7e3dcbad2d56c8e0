"""Program generation (MODEL.md §5): macros, motions, detection algorithms, risk, JSON Schema."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from dlovr.model.discrete import parse_discrete_situation as P
from dlovr.model.program import (
    DETECTORS,
    PoseTrack,
    TimedSituation,
    compile_program,
    program_schema,
)
from dlovr.transforms import matrix_to_rotvec, quat_to_matrix

FIG11 = Path(__file__).parents[1] / "data" / "fig11.txt"


def fig11_states():
    lines = [ln for ln in FIG11.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    return [TimedSituation(float(k), 1.0, P(ln)) for k, ln in enumerate(lines)]


def straight_track(n=11):
    t = np.arange(n, dtype=float)
    pos = np.stack([0.1 * t, np.zeros(n), np.full(n, 0.5)], axis=1)
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return PoseTrack(t, pos, quat)


def test_fig11_program_has_one_macro_per_classed_transition_in_order():
    prog = compile_program(fig11_states(), straight_track(), name="peg", source="fig11.txt")
    assert [m.label for m in prog.macros] == ["E", "C", "C", "C", "E", "I", "S,E", "E"]
    assert prog.summary == {"macros": 8, "risky": 2}
    assert [m.risky for m in prog.macros] == [False, False, False, False, False, True, True, False]
    s_e = prog.macros[6]
    assert [d.algorithm for d in s_e.detection] == [DETECTORS["S"]["algorithm"], DETECTORS["E"]["algorithm"]]
    assert s_e.to_contacts[0].state == "E/E^LS[block.F2,holeB.F5]"


def test_a_step_without_class_extends_the_next_macros_motion():
    prog = compile_program(fig11_states(), straight_track())
    # step 4 (index 3) has no class: the macro of step 5 moves from t=2 (step 3) to t=4
    m = prog.macros[2]
    assert m.t == 4.0 and m.motion.duration == 2.0
    np.testing.assert_allclose(m.motion.world, [0.2, 0.0, 0.0])


def test_relative_motion_is_in_the_gripper_frame():
    t = np.array([0.0, 1.0])
    q_yaw90 = [math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]
    track = PoseTrack(t, np.array([[0, 0, 0], [0.0, 0.1, 0.0]]), np.array([q_yaw90, q_yaw90]))
    states = [
        TimedSituation(0.0, 1.0, P("V/G & E/N & V/N")),
        TimedSituation(1.0, 1.0, P("V/G & E/N & V/F[t.F1]")),
    ]
    m = compile_program(states, track).macros[0]
    np.testing.assert_allclose(m.motion.world, [0, 0.1, 0], atol=1e-9)
    np.testing.assert_allclose(m.motion.relative, [0.1, 0, 0], atol=1e-9)  # world +y is gripper +x


def test_rotation_vector():
    for axis, deg in [((0, 0, 1), 30.0), ((1, 0, 0), 179.99), ((0, 1, 0), 0.0)]:
        a = math.radians(deg) / 2
        q = [math.cos(a), *(math.sin(a) * np.array(axis))]
        np.testing.assert_allclose(
            matrix_to_rotvec(quat_to_matrix(q)), np.array(axis) * math.radians(deg), atol=1e-6
        )


def test_expected_contact_vectors_come_from_the_contacts():
    a = P("V/G & E/N & V/N")
    b = P("V/G & E/N & V/F[t.F1]")
    from dataclasses import replace

    b = type(b)((b.contacts[0], b.contacts[1], replace(b.contacts[2], vector=(0.0, 0.0, -1.0))))
    prog = compile_program([TimedSituation(0, 1, a), TimedSituation(1, 1, b, force=2.0)], straight_track(2))
    m = prog.macros[0]
    assert m.to_contacts[0].vector == (0.0, 0.0, -1.0)
    assert m.detection[0].params["force_threshold_n"] == 1.0  # half the demonstrated force


def test_program_json_validates_against_the_shipped_schema_and_is_deterministic():
    prog = compile_program(fig11_states(), straight_track(), name="peg", source="fig11.txt")
    data = json.loads(prog.dumps())
    jsonschema.validate(data, program_schema())
    assert data["version"] == 1
    assert (
        prog.dumps()
        == compile_program(fig11_states(), straight_track(), name="peg", source="fig11.txt").dumps()
    )
    bad = dict(data, version=2)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, program_schema())


def test_listing_is_readable():
    text = compile_program(fig11_states(), straight_track(), name="peg").listing()
    assert "S,E" in text and "RISKY" in text and text.strip().endswith("8 macros, 2 risky")


def test_pose_track_validation():
    with pytest.raises(ValueError):
        PoseTrack(np.array([1.0, 0.0]), np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1)))
    with pytest.raises(ValueError):
        PoseTrack(np.array([0.0]), np.zeros((2, 3)), np.zeros((1, 4)))
