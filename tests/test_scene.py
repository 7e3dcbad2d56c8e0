"""Scene files: built-in scenes, validation errors (one test per kind), the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import trimesh
from click.testing import CliRunner

from dlovr.cli import main
from dlovr.geometry import SceneGeometry
from dlovr.geometry.scene_checks import load_checked_scene
from dlovr.scene import SceneError, builtin_scenes, load_scene


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DLOVR_CACHE_DIR", str(tmp_path / "cache"))


HEADER = """
name = "t"
description = "test scene"
[dlo]
length = 0.5
radius = 0.005
segments = 20
young = 2e7
damping = 0.01
mass = 0.05
[gripper]
pos = [0.0, 0.0, 0.5]
quat = [1, 0, 0, 0]
[[objects]]
name = "table"
box = { size = [1.0, 1.0, 0.05], pos = [0.0, 0.0, -0.025] }
"""


def write(tmp_path: Path, text: str, meshes: dict[str, trimesh.Trimesh] | None = None) -> Path:
    for name, m in (meshes or {}).items():
        p = tmp_path / name
        p.parent.mkdir(parents=True, exist_ok=True)
        m.export(p)
    p = tmp_path / "scene.toml"
    p.write_text(text, encoding="utf-8")
    return p


# --------------------------------------------------------------------------------------------------
# Built-in scenes
# --------------------------------------------------------------------------------------------------


def test_builtin_scenes_listed_and_load():
    names = [n for n, _ in builtin_scenes()]
    assert {"peg_in_hole", "edges", "l_block", "table"} <= set(names)
    for name in ("peg_in_hole", "edges", "l_block", "table"):
        s = load_scene(name)
        assert s.name == name and s.description
        assert s.objects[0].name == "table"
        geom = SceneGeometry.from_scene(s)
        for o in geom.objects:
            assert not o.approximate
            for p in o.pieces:
                assert len(p.faces) >= 4


def test_edges_scene_has_the_four_edges_within_single_objects():
    geom = SceneGeometry.from_scene(load_scene("edges"))
    want = {"concave90": (False, 90.0), "concave175": (False, 175.0), "convex185": (True, 185.0),
            "convex270": (True, 270.0)}
    for obj, (convex, opening) in want.items():
        o = geom.object(obj)
        assert len(o.pieces) >= 2  # non-convex object
        # the edge lies at the object's local x = 0, between two faces of the upper surface
        edges = [e for e in o.edges if e.convex == convex and e.length == pytest.approx(0.4)]
        assert any(e.opening_deg == pytest.approx(opening, abs=1e-6) for e in edges), (obj, o.edges)


def test_face_names_identical_across_loads():
    a = SceneGeometry.from_scene(load_scene("peg_in_hole")).describe()
    b = SceneGeometry.from_scene(load_scene("peg_in_hole")).describe()
    assert a == b


def test_scene_by_path_and_mesh_relative_to_file(tmp_path):
    mesh = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    p = write(tmp_path, HEADER + '[[objects]]\nname = "cube"\nmesh = "m/cube.obj"\npos = [0, 0, 0.05]\n',
              {"m/cube.obj": mesh})
    s = load_scene(str(p))
    assert s.object("cube").mesh_path == (tmp_path / "m" / "cube.obj").resolve()
    assert s.params.critical_angle_deg == 170


# --------------------------------------------------------------------------------------------------
# Errors: one per kind, each message names the file, the key or object, and the problem
# --------------------------------------------------------------------------------------------------


def error(tmp_path, text, meshes=None) -> str:
    p = write(tmp_path, text, meshes)
    with pytest.raises(SceneError) as ei:
        load_checked_scene(str(p))
    msg = str(ei.value)
    assert msg.startswith(str(p)) and "\n" not in msg
    return msg


def test_error_syntax(tmp_path):
    assert "invalid TOML" in error(tmp_path, HEADER + "\n[dlo\n")


def test_error_unknown_key(tmp_path):
    msg = error(tmp_path, HEADER.replace("segments = 20", "segments = 20\nstiffness = 3"))
    assert "dlo.stiffness: unknown key" in msg


def test_error_unknown_object_key(tmp_path):
    msg = error(tmp_path, HEADER + '[[objects]]\nname = "b"\nbox = { size = [0.1, 0.1, 0.1] }\ncolour = 1\n')
    assert "objects[1].colour: unknown key" in msg


def test_error_missing_mesh(tmp_path):
    msg = error(tmp_path, HEADER + '[[objects]]\nname = "peg"\nmesh = "nothere.obj"\n')
    assert "object 'peg'.mesh" in msg and "not found" in msg


def test_error_mesh_outside_scene_directory(tmp_path):
    msg = error(tmp_path, HEADER + '[[objects]]\nname = "peg"\nmesh = "../x.obj"\n')
    assert "object 'peg'.mesh" in msg and "inside the scene file's directory" in msg


def test_error_not_watertight(tmp_path):
    box = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    open_box = trimesh.Trimesh(box.vertices, box.faces[1:], process=False)
    msg = error(tmp_path, HEADER + '[[objects]]\nname = "cup"\nmesh = "open.obj"\npos = [0, 0, 0.05]\n',
                {"open.obj": open_box})
    assert "object 'cup'" in msg and "not watertight" in msg


def test_error_self_intersecting(tmp_path):
    a = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    b = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    b.apply_translation([0.05, 0.05, 0.05])
    both = trimesh.util.concatenate([a, b])
    msg = error(tmp_path, HEADER + '[[objects]]\nname = "knot"\nmesh = "two.obj"\npos = [0, 0, 0.05]\n',
                {"two.obj": both})
    assert "object 'knot'" in msg and "self-intersecting" in msg


def test_error_negative_size(tmp_path):
    msg = error(tmp_path, HEADER + '[[objects]]\nname = "b"\nbox = { size = [0.1, -0.1, 0.1] }\n')
    assert "object 'b'.box.size" in msg and "positive" in msg


def test_error_negative_radius(tmp_path):
    msg = error(tmp_path, HEADER.replace("radius = 0.005", "radius = -0.005"))
    assert "dlo.radius" in msg and "positive" in msg


def test_error_objects_overlap(tmp_path):
    msg = error(
        tmp_path, HEADER + '[[objects]]\nname = "b"\nbox = { size = [0.1, 0.1, 0.1], pos = [0, 0, 0.0] }\n'
    )
    assert "objects 'table' and 'b'" in msg and "overlap" in msg


def test_load_scene_checks_the_file_and_not_the_geometry(tmp_path):
    """``load_scene`` reads and checks the file alone; the checks that need meshes are
    ``dlovr.geometry.scene_checks``'s, and ``dlovr/scene.py`` imports no geometry at all."""
    import ast

    import dlovr.scene

    p = write(
        tmp_path, HEADER + '[[objects]]\nname = "b"\nbox = { size = [0.1, 0.1, 0.1], pos = [0, 0, 0.0] }\n'
    )
    assert [o.name for o in load_scene(p).objects] == ["table", "b"]
    with pytest.raises(SceneError, match="overlap"):
        load_checked_scene(p)
    tree = ast.parse(Path(dlovr.scene.__file__).read_text())
    names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    names += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    assert not [n for n in names if n.startswith("dlovr.geometry") or n.split(".")[0] == "trimesh"]


def test_touching_objects_do_not_overlap(tmp_path):
    p = write(
        tmp_path, HEADER + '[[objects]]\nname = "b"\nbox = { size = [0.1, 0.1, 0.1], pos = [0, 0, 0.05] }\n'
    )
    assert len(load_checked_scene(str(p)).objects) == 2


def test_error_cable_longer_than_scene(tmp_path):
    msg = error(tmp_path, HEADER.replace("length = 0.5", "length = 5.0"))
    assert "dlo.length" in msg and "longer than the scene" in msg


@pytest.mark.parametrize(
    ("old", "new", "expected"),
    [
        ("segments = 20", "segments = 100000", "dlo.segments: must be an integer from 2 to 200, got 100000"),
        ("segments = 20", "segments = 201", "dlo.segments: must be an integer from 2 to 200, got 201"),
        ("segments = 20", "segments = 1", "dlo.segments: must be an integer from 2 to 200, got 1"),
        ("length = 0.5", "length = 1e6", "dlo.length: must be at most 10 m"),
        ("radius = 0.005", "radius = 0.25", "dlo.radius: must be less than half the length"),
    ],
)
def test_error_cable_beyond_the_documented_limits(tmp_path, old, new, expected):
    msg = error(tmp_path, HEADER.replace(old, new))
    assert expected in msg and "\n" not in msg


def test_the_segment_limit_itself_is_accepted(tmp_path):
    p = write(tmp_path, HEADER.replace("segments = 20", "segments = 200"))
    assert load_scene(p).dlo.segments == 200


def test_error_too_many_objects(tmp_path):
    boxes = "".join(
        f'[[objects]]\nname = "b{i}"\nbox = {{ size = [0.01, 0.01, 0.01] }}\n'
        for i in range(64)
    )
    msg = error(tmp_path, HEADER + boxes)
    assert "objects: 65 objects, at most 64 allowed" in msg


def test_error_unknown_scene_name():
    with pytest.raises(SceneError, match="no built-in scene of that name"):
        load_scene("no_such_scene")


# --------------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------------


def test_cli_scenes():
    r = CliRunner().invoke(main, ["scenes"])
    assert r.exit_code == 0, r.output
    for name in ("peg_in_hole", "edges", "l_block", "table"):
        assert name in r.output


def test_cli_scene_show_json():
    r = CliRunner().invoke(main, ["scene", "show", "l_block", "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    lb = next(o for o in d["objects"] if o["name"] == "lblock")
    assert len(lb["pieces"]) == 2 and all(p["kind"] == "exact" for p in lb["pieces"])
    assert lb["faces"][0]["name"] == "lblock.F1"
    kinds = {f["kind"] for p in lb["pieces"] for f in p["faces"]}
    assert "internal" in kinds and "external" in kinds
    assert any(e["kind"] == "concave" and e["opening_deg"] == pytest.approx(90) for e in lb["edges"])


def test_cli_scene_show_text():
    r = CliRunner().invoke(main, ["scene", "show", "peg_in_hole"])
    assert r.exit_code == 0, r.output
    assert "object holeblock" in r.output and "holeblock.F1" in r.output and "edge " in r.output


def test_cli_bad_scene_exit_code_2_no_traceback(tmp_path):
    p = write(tmp_path, HEADER + "\n[dlo\n")
    r = CliRunner().invoke(main, ["scene", "show", str(p)])
    assert r.exit_code == 2
    assert "Traceback" not in r.output and "invalid TOML" in r.output
    assert r.output.count("\n") == 1


def test_the_limits_are_documented_as_the_code_has_them():
    from dlovr.geometry import mesh
    from dlovr.inputs import LIMITS

    doc = (Path(__file__).resolve().parent.parent / "docs" / "scenes.md").read_text()
    assert f"| `dlo.segments` | 2 to {int(LIMITS['dlo_segments'])} |" in doc
    assert f"| `dlo.length` | at most {LIMITS['dlo_length_m']:g} m" in doc
    assert f"| objects | at most {int(LIMITS['scene_objects'])} |" in doc
    assert f"{mesh.MAX_MESH_TRIANGLES:,} triangles" in doc
    assert f"at most {int(LIMITS['script_waypoints']):,}" in doc
    assert f"at most {LIMITS['script_duration_s']:g} s in all" in doc
