"""Script files: validation errors and waypoint interpolation (pure, no MuJoCo)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from dlovr.script import ScriptError, load_script, parse_script
from dlovr.transforms import quat_rotate, slerp

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "demo.script.toml"
    p.write_text(text)
    return p


def test_load_and_interpolate(tmp_path: Path) -> None:
    p = _write(
        tmp_path,
        """
scene = "table"
[[waypoints]]
pos = [0.0, 0.0, 1.0]
duration = 1.0
hold = 0.5
[[waypoints]]
pos = [1.0, 0.0, 1.0]
quat = [0.7071068, 0.0, 0.0, 0.7071068]
duration = 2.0
""",
    )
    s = load_script(p)
    assert s.scene == "table"
    assert s.total_duration == pytest.approx(3.5)
    start = ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])
    pos, quat = s.target_at(0.5, *start)
    assert np.allclose(pos, [0, 0, 0.5])
    pos, _ = s.target_at(1.2, *start)
    assert np.allclose(pos, [0, 0, 1])  # holding
    pos, quat = s.target_at(2.5, *start)  # halfway to the second waypoint
    assert np.allclose(pos, [0.5, 0, 1])
    assert np.allclose(quat, [math.cos(math.pi / 8), 0, 0, math.sin(math.pi / 8)], atol=1e-6)
    pos, quat = s.target_at(99.0, *start)
    assert np.allclose(pos, [1, 0, 1])
    # without a start pose, the first waypoint is the start
    pos, _ = s.target_at(0.3)
    assert np.allclose(pos, [0, 0, 1])


def test_slerp_and_rotate() -> None:
    q0 = np.array([1.0, 0, 0, 0])
    q1 = np.array([math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)])  # 90° about z
    q = slerp(q0, q1, 0.5)
    assert np.allclose(quat_rotate(q, np.array([1.0, 0, 0])), [math.sqrt(0.5), math.sqrt(0.5), 0])
    assert np.allclose(slerp(q0, -q1, 1.0), q1) or np.allclose(slerp(q0, -q1, 1.0), -q1)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("[[waypoints]]\npos=[0,0]\nduration=1\n", "waypoints[0].pos: must be a list of 3 numbers"),
        ("[[waypoints]]\npos=[0,0,1]\n", "waypoints[0].duration: missing"),
        (
            "[[waypoints]]\npos=[0,0,1]\nduration=1\n[[waypoints]]\npos=[0,0,1]\nduration=-1\n",
            "waypoints[1].duration: must be positive, got -1",
        ),
        (
            "[[waypoints]]\npos=[0,0,1]\nduration=1\nhold=-0.1\n",
            "waypoints[0].hold: must not be negative, got -0.1",
        ),
        (
            "[[waypoints]]\npos=[0,0,1]\nduration=1\nquat=[0,0,0,0]\n",
            "waypoints[0].quat: must not be all zeros",
        ),
        (
            "[[waypoints]]\npos=[0,0,'a']\nduration=1\n",
            "waypoints[0].pos[2]: must be a finite number, got 'a'",
        ),
        ("[[waypoints]]\npos=[0,0,1]\nduration=1\nspeed=3\n", "waypoints[0].speed: unknown key"),
        ("scene = 3\n[[waypoints]]\npos=[0,0,1]\nduration=1\n", "scene: must be a scene name or path"),
        ("scene = 'x'\n", "waypoints: missing"),
        ("waypoints = [\n", "invalid TOML"),
        (
            "foo = 1\n[[waypoints]]\npos=[0,0,1]\nduration=1\n",
            "foo: unknown key (allowed: description, scene, waypoints)",
        ),
        ("[[waypoints]]\npos=[0,0,1]\nduration=1e9\n", "the script lasts 1e+09 s"),
        (
            "[[waypoints]]\npos=[0,0,1]\nduration=300\nhold=300.5\n",
            "the script lasts 600.5 s (durations and holds), at most 600 s",
        ),
        ("[[waypoints]]\npos=[0,0,1]\nduration=0.01\n" * 10_001, "10001 waypoints, at most 10000 allowed"),
    ],
)
def test_errors_are_one_line_and_name_file_waypoint_key(tmp_path: Path, text: str, expected: str) -> None:
    p = _write(tmp_path, text)
    with pytest.raises(ScriptError) as ei:
        load_script(p)
    msg = str(ei.value)
    assert "\n" not in msg
    assert msg.startswith(str(p))
    assert expected in msg


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ScriptError, match="no such script file"):
        load_script(tmp_path / "nope.toml")


def test_parse_script_is_a_value_error() -> None:
    with pytest.raises(ValueError):
        parse_script({"waypoints": []}, "x")


@pytest.mark.parametrize("path", sorted(SCENES.glob("*.script.toml")), ids=lambda p: p.name)
def test_builtin_scripts_are_valid(path: Path) -> None:
    s = load_script(path)
    assert s.scene and s.total_duration > 0


def test_plan_phases_at_their_boundaries_and_returns_fresh_arrays() -> None:
    s = parse_script(
        {
            "waypoints": [
                {"pos": [1.0, 0.0, 0.0], "duration": 1.0},  # no hold: the next move starts at once
                {"pos": [1.0, 2.0, 0.0], "duration": 2.0, "hold": 1.0},
                {"pos": [0.0, 2.0, 0.0], "quat": [0.0, 0.0, 0.0, 2.0], "duration": 1.0},
            ]
        }
    )
    plan = s.plan((0.0, 0.0, 0.0), (2.0, 0.0, 0.0, 0.0))
    assert plan.ends == (1.0, 1.0, 3.0, 4.0, 5.0, 5.0)
    expect = {
        -1.0: [0, 0, 0],
        0.0: [0, 0, 0],
        0.5: [0.5, 0, 0],
        1.0: [1, 0, 0],  # first waypoint reached: the second move starts
        2.0: [1, 1, 0],
        3.0: [1, 2, 0],  # holding
        3.5: [1, 2, 0],
        4.0: [1, 2, 0],  # the hold ends: the third move starts
        4.5: [0.5, 2, 0],
        5.0: [0, 2, 0],
        9.0: [0, 2, 0],
    }
    for t, pos in expect.items():
        p, q = plan.at(t)
        assert p.tolist() == pos, t
        assert math.isclose(float(np.linalg.norm(q)), 1.0)
    assert plan.at(3.5)[1].tolist() == [1.0, 0.0, 0.0, 0.0]  # start quat, normalised, kept
    assert plan.at(9.0)[1].tolist() == [0.0, 0.0, 0.0, 1.0]
    # the returned arrays are the caller's: changing them does not change the plan
    for t in (-1.0, 3.5, 9.0):
        p, q = plan.at(t)
        p[:] = 7.0
        q[:] = 7.0
        assert plan.at(t)[0].tolist() == expect[t]
        assert 7.0 not in plan.at(t)[1].tolist()
    # at the end of a move the waypoint is held exactly (interpolating would give 0.09999999999999998)
    held = parse_script({"waypoints": [{"pos": [0.1, 0.0, 0.0], "duration": 1.0, "hold": 0.5}]})
    assert held.plan((0.7, 0.0, 0.0)).at(1.0)[0].tolist() == [0.1, 0.0, 0.0]


def test_the_limits_themselves_are_accepted(tmp_path: Path) -> None:
    p = _write(tmp_path, "[[waypoints]]\npos=[0,0,1]\nduration=0.05\n" * 10_000 + "")
    assert len(load_script(p).waypoints) == 10_000
    p = _write(tmp_path, "[[waypoints]]\npos=[0,0,1]\nduration=300\nhold=300\n")
    assert load_script(p).total_duration == 600


def test_a_scene_path_in_a_script_is_relative_to_the_script(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "demos").mkdir()
    p = tmp_path / "demos" / "x.script.toml"
    p.write_text('scene = "../scenes/my.toml"\n[[waypoints]]\npos=[0,0,1]\nduration=1\n')
    monkeypatch.chdir(SCENES)  # anywhere but the script's folder
    want = (tmp_path / "scenes" / "my.toml").resolve()
    for where in (p, os.path.relpath(p, SCENES)):
        scene = load_script(where).scene
        assert scene is not None and Path(scene).resolve() == want
    p.write_text('scene = "peg_in_hole"\n[[waypoints]]\npos=[0,0,1]\nduration=1\n')
    assert load_script(p).scene == "peg_in_hole"  # a name is a built-in scene
