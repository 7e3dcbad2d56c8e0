"""Program generation (docs/model.md, paper §VI): macros, changing contacts, final macro, motions,
detection algorithms, risk, pinches, JSON Schema."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from dlovr.model.derivation import WrenchSeries
from dlovr.model.discrete import parse_discrete_situation as P
from dlovr.model.program import (
    DETECTORS,
    PROGRAM_VERSION,
    PoseTrack,
    TimedSituation,
    compile_program,
    program_schema,
    risk,
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
    assert [m.label for m in prog.macros] == ["E", "C", "C", "C", "E", "I", "S,E", "E", "end"]
    assert prog.summary == {"macros": 9, "risky": 2, "caution": 0}
    assert [m.risky for m in prog.macros] == [False, False, False, False, False, True, True, False, False]
    s_e = prog.macros[6]
    assert [d.algorithm for d in s_e.detection] == [DETECTORS["S"]["algorithm"], DETECTORS["E"]["algorithm"]]
    assert s_e.to_contacts[0].state == "E/E^LS[block.F2,holeB.F5]"


def test_each_macro_names_the_principal_contacts_that_change():
    prog = compile_program(fig11_states(), straight_track())

    def named(m):
        def state(c):
            return c and c.state

        return [(",".join(c.classes), state(c.from_contact), state(c.to_contact)) for c in m.changes]

    assert named(prog.macros[0]) == [("E", None, "V/F[block.F1]")]  # established: from N
    assert named(prog.macros[2]) == [("C", "E/F[block.F1]", "E/E^P[block.F1,block.F2]")]  # Fig. 11 step 5
    assert named(prog.macros[6]) == [
        ("S,E", "V/VI[block.F2,holeA.F3,holeA.F4]", "E/E^LS[block.F2,holeB.F5]")
    ]
    # step 10: E/E^LS stays, the new principal V/VS is established beside it
    assert named(prog.macros[7]) == [("E", None, "V/VS[block.F2,holeB.F5,holeC.F7]")]


def test_the_motion_after_the_last_classed_transition_is_a_final_macro():
    states = fig11_states()[:4]  # ... step 3 (C), step 4 (-): the final macro starts at step 3
    prog = compile_program(states, straight_track())
    final = prog.macros[-1]
    assert [m.kind for m in prog.macros] == ["transition", "transition", "final"]
    assert final.label == "end" and final.classes == () and final.detection == () and final.changes == ()
    assert final.risk == "none" and final.t == 10.0  # the end of the pose track
    assert final.from_situation == states[2].situation.format()
    assert final.to_situation == states[3].situation.format()
    assert final.motion.duration == 8.0
    np.testing.assert_allclose(final.motion.world, [0.8, 0.0, 0.0])
    # a demonstration without a classed transition is one final macro
    only = compile_program(fig11_states()[:1], straight_track())
    assert [m.kind for m in only.macros] == ["final"] and only.macros[0].motion.duration == 10.0


def test_risk_is_none_caution_or_risky():
    assert [risk(c) for c in [(), ("C",), ("E",), ("T",), ("I",), ("S", "E"), ("T", "C")]] == [
        "none", "none", "none", "caution", "risky", "risky", "caution",
    ]
    a, b = P("V/G & E/N & E/F[a.F1] & V/N"), P("V/G & E/N & E/E^LT[a.F1,a.F2] & V/N")
    prog = compile_program([TimedSituation(0, 1, a), TimedSituation(1, 1, b)], straight_track(2))
    assert prog.macros[0].risk == "caution" and prog.summary["caution"] == 1


def test_a_flight_compiles_to_one_S_E_macro():
    ridge, landed = P("V/G & E/N & V/E^LI[a.F1,a.F2]"), P("V/G & E/N & V/F[a.F2]")
    states = [TimedSituation(0, 1, ridge), TimedSituation(1.1, 1, landed, through_free=True)]
    assert compile_program(states, straight_track(3)).macros[0].classes == ("S", "E")
    states[1] = TimedSituation(1.1, 1, landed)
    assert compile_program(states, straight_track(3)).macros[0].classes == ("S",)


def test_a_pinch_is_expected_with_its_zero_vector_and_axis():
    from dataclasses import replace

    a = P("V/G & E/N & E/F[a.F1] & V/N")
    b = P("V/G & E/N & E/F[a.F1,b.F2] & V/N")
    pinch = replace(b.contacts[2], vector=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0))
    b = type(b)((b.contacts[0], b.contacts[1], pinch, b.contacts[3]))
    prog = compile_program([TimedSituation(0, 1, a), TimedSituation(1, 1, b)], straight_track(2))
    (change,) = prog.macros[0].changes
    assert change.to_contact.vector == (0.0, 0.0, 0.0) and change.to_contact.axis == (0.0, 0.0, 1.0)
    data = json.loads(prog.dumps())
    jsonschema.validate(data, program_schema())
    assert data["macros"][0]["changes"][0]["to_contact"]["axis"] == [0.0, 0.0, 1.0]
    # its E detection is derived along the axis (in the sign the step took)
    t = np.arange(0.0, 2.0, 0.01)
    f = np.where((t < 1.0)[:, None], 0.0, np.array([0.3, 0.0, -0.4]))
    states = [TimedSituation(0, 1, a), TimedSituation(1, 1, b)]
    prog = compile_program(states, straight_track(2), wrench=WrenchSeries(t, f, 0 * f))
    (det,) = prog.macros[0].detection
    assert det.params["step_n"] == pytest.approx(0.4)
    assert "step along -axis" in det.derivation["force_threshold_n"]


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
    # no wrench series: the class's defaults, each marked as such
    assert m.detection[0].params["force_threshold_n"] == 0.5
    assert m.detection[0].derivation["force_threshold_n"].startswith("default: no wrench signal")


def test_program_json_validates_against_the_shipped_schema_and_is_deterministic():
    prog = compile_program(fig11_states(), straight_track(), name="peg", source="fig11.txt")
    data = json.loads(prog.dumps())
    jsonschema.validate(data, program_schema())
    assert data["version"] == 2 == PROGRAM_VERSION
    assert (
        prog.dumps()
        == compile_program(fig11_states(), straight_track(), name="peg", source="fig11.txt").dumps()
    )
    bad = dict(data, version=1)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, program_schema())
    final_with_detection = dict(data["macros"][-1], detection=data["macros"][0]["detection"])
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(dict(data, macros=[final_with_detection]), program_schema())
    without_changes = dict(data["macros"][0], changes=[])
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(dict(data, macros=[without_changes]), program_schema())


def test_listing_is_readable():
    text = compile_program(fig11_states(), straight_track(), name="peg").listing()
    assert "S,E" in text and "risk risky" in text
    assert "E/F[block.F1] -> E/E^P[block.F1,block.F2]" in text and "N -> V/F[block.F1]" in text
    assert "to the demonstrated end pose (no detection)" in text
    assert text.strip().endswith("9 macros (the last one final), 2 risky, 0 caution")


def test_pose_track_validation():
    with pytest.raises(ValueError):
        PoseTrack(np.array([1.0, 0.0]), np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1)))
    with pytest.raises(ValueError):
        PoseTrack(np.array([0.0]), np.zeros((2, 3)), np.zeros((1, 4)))


def test_the_one_program_type_reads_back_what_it_writes():
    """Program.from_json reads the compiler's JSON into the same Program (byte for byte when written
    again); the reader's classes, risks and version come from the shipped schema."""
    from dlovr.inputs import InputError
    from dlovr.model.program import Program, ProgramError, readable_versions

    prog = compile_program(fig11_states(), straight_track(), name="peg", source="fig11.txt")
    back = Program.from_json(json.loads(prog.dumps()), "peg.program.json")
    assert back.dumps() == prog.dumps()
    assert back.macros == prog.macros and back.summary == prog.summary
    assert [m.index for m in back.classed] == list(range(1, len(prog.macros)))
    assert back.final == prog.macros[-1] and back.final.final
    assert str(back.path) == "peg.program.json" and back.scene is None
    schema = program_schema()
    assert readable_versions()[-1] == schema["properties"]["version"]["const"] == PROGRAM_VERSION
    assert set(schema["$defs"]["class"]["enum"]) == set(DETECTORS)
    raw = json.loads(prog.dumps())
    raw["macros"][0]["risk"] = "dire"
    must = r"^p\.json: macros\[0\]\.risk: must be one of none, caution, risky"
    with pytest.raises(ProgramError, match=must):
        Program.from_json(raw, "p.json")
    assert issubclass(ProgramError, InputError)


def test_a_format_1_program_is_read_with_its_risk_and_summary_derived():
    """Format 1 (no kind, risk or changes; the final macro under ``final``) still reads."""
    from dlovr.model.program import Program

    prog = compile_program(fig11_states(), straight_track(), name="peg", source="fig11.txt")
    raw = json.loads(prog.dumps())
    for m in raw["macros"]:
        for k in ("kind", "risk", "changes"):
            m.pop(k)
    raw["final"] = raw["macros"].pop()
    raw["version"] = 1
    back = Program.from_json(raw)
    assert [m.risk for m in back.macros] == [m.risk for m in prog.macros]
    assert back.summary == prog.summary and back.final is not None and back.final.kind == "final"


# -- chatter (docs/model.md, section 6) --------------------------------------------------------------


def _seq(*items):
    """TimedSituations from (t, duration, situation text)."""
    return [TimedSituation(t, d, P(s)) for t, d, s in items]


_N = "V/G & E/N & V/N"
_VF = "V/G & E/N & V/F[table.F1]"
_EF = "V/G & E/N & E/F[table.F1] & V/N"


def test_a_brief_flip_back_and_forth_with_little_motion_is_not_two_macros():
    from dlovr.model.program import remove_chatter

    states = _seq((0, 1, _N), (1, 2, _VF), (3, 0.02, _EF), (3.02, 0.3, _VF), (3.32, 0.01, _EF),
                  (3.33, 2, _VF), (5.33, 1, _EF))
    track = straight_track(8)  # 0.1 m/s: the flips move the gripper a few mm
    kept = remove_chatter(states, track)
    assert [k.situation.format() for k in kept] == [_N, _VF, _EF]
    assert kept[1].t == 1 and kept[1].duration == pytest.approx(4.33)
    prog = compile_program(states, track)
    assert [m.label for m in prog.macros] == ["E", "C", "end"]
    assert [m.label for m in compile_program(states, track, chatter=None).macros] == [
        "E", "C", "C", "C", "C", "C", "end"]


def test_laying_down_dragging_and_lifting_stays_four_transitions():
    # E, C, C, E: the drag (E/F) holds seconds and moves the gripper decimetres: a real detour
    states = _seq((0, 1, _N), (1, 1, _VF), (2, 3, _EF), (5, 1, _VF), (6, 1, _N))
    prog = compile_program(states, straight_track(8))
    assert [m.label for m in prog.macros] == ["E", "C", "C", "E", "end"]


def test_a_quick_return_with_much_motion_is_kept():
    from dlovr.model.program import ChatterRules, remove_chatter

    states = _seq((0, 1, _VF), (1, 0.5, _EF), (1.5, 1, _VF))
    pos = np.array([[0, 0, 0], [0, 0, 0], [0.2, 0, 0], [0.2, 0, 0]])
    fast = PoseTrack(np.array([0.0, 1.0, 1.5, 3.0]), pos, np.tile([1.0, 0, 0, 0], (4, 1)))
    assert len(remove_chatter(states, fast)) == 3
    assert len(remove_chatter(states, straight_track(4), ChatterRules(max_s=0.4))) == 3
    assert len(remove_chatter(states, straight_track(4))) == 1


def test_a_landing_that_settles_at_once_lands_where_it_settles_and_a_new_contact_stays():
    from dlovr.model.program import remove_chatter

    vi = "V/G & E/N & V/VI[b.F3,b.F5,h.F2,h.F11]"
    ef = "V/G & E/N & E/F[h.F6] & V/N"
    els = "V/G & E/N & V/E^LS[h.F1,h.F6]"
    vs = "V/G & E/N & V/VS[b.F5,h.F1,h.F6]"
    states = [TimedSituation(0, 1, P(vi)), TimedSituation(1.1, 0.03, P(ef), through_free=True),
              TimedSituation(1.13, 0.02, P(els)), TimedSituation(1.15, 1, P(vs))]
    kept = remove_chatter(states, straight_track(4))
    # the segment's brief touch of the wall settles into the tip in the groove (C, no new contact);
    # the groove -> corner step makes a new contact (E): kept however short
    assert [k.situation.format() for k in kept] == [vi, els, vs]
    assert kept[1].through_free and kept[1].t == 1.1
    assert [m.label for m in compile_program(states, straight_track(4)).macros] == ["S,E", "E", "end"]


def test_an_excursion_through_several_situations_that_comes_back_at_once_is_chatter():
    from dlovr.model.program import remove_chatter

    hop = "V/G & E/N & E/F[table.F1] & E/N & V/N"
    states = _seq((0, 1, _N), (1, 2, _EF), (3, 0.036, _N), (3.036, 0.04, hop), (3.076, 2, _EF),
                  (5.076, 1, _VF))
    kept = remove_chatter(states, straight_track(8))
    assert [k.situation.format() for k in kept] == [_N, _EF, _VF]
    assert kept[1].duration == pytest.approx(4.076)


def test_a_swing_off_and_back_onto_the_same_object_is_one_transition():
    """docs/model.md section 6: the cable on the block's edge swings off every contact for 0.8 s while
    the hand barely moves and lands on the block's side face: the step edge -> face (``C``), not a
    release and a landing (``E, E``). Onto another object, or with much motion, it stays ``E, E``."""
    from dlovr.model.program import remove_chatter

    edge = "V/G & E/N & E/E^P[b.F1,b.F3] & E/N & V/N"
    face = "V/G & E/N & E/F[b.F3] & V/N"
    groove = "V/G & E/N & V/E^LS[b.F3,h.F2]"
    t = np.arange(0.0, 8.0, 0.1)

    def moving(speed):  # the gripper along x at ``speed`` m/s, sampled every 0.1 s
        pos = np.stack([speed * t, np.zeros(len(t)), np.full(len(t), 0.5)], axis=1)
        return PoseTrack(t, pos, np.tile([1.0, 0, 0, 0], (len(t), 1)))

    slow = moving(0.0125)  # 1 cm in the 0.8 s off the block
    states = _seq((0, 1, _N), (1, 2, edge), (3, 0.8, _N), (3.8, 2, face), (5.8, 1, groove))
    kept = remove_chatter(states, slow)
    assert [k.situation.format() for k in kept] == [_N, edge, face, groove]
    assert kept[1].duration == pytest.approx(2.8) and kept[2].t == 3.8
    assert [m.label for m in compile_program(states, slow).macros] == ["E", "C", "E", "end"]
    as_recorded = compile_program(states, slow, chatter=None)
    assert [m.label for m in as_recorded.macros] == ["E", "E", "E", "E", "end"]
    # landing on another object, or after 8 cm of motion: a release and a landing
    other = _seq((0, 1, _N), (1, 2, edge), (3, 0.8, _N), (3.8, 2, "V/G & E/N & E/F[h.F2] & V/N"))
    assert len(remove_chatter(other, slow)) == 4
    assert len(remove_chatter(states, moving(0.1))) == 5
