"""Geometry: decomposition, face names, point classification, pair facts, edge table."""

from __future__ import annotations

import math

import manifold3d as M
import numpy as np
import pytest
import trimesh

from dlovr.geometry import (
    SceneGeometry,
    box_mesh,
    build_object,
    decompose,
    object_faces,
    prism_mesh,
)
from dlovr.geometry.mesh import _to_trimesh
from dlovr.transforms import pose_matrix


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DLOVR_CACHE_DIR", str(tmp_path / "cache"))


def cube(lo, hi) -> M.Manifold:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return M.Manifold.cube(list(hi - lo)).translate(list(lo))


SHAPES = {
    "L": (lambda: _to_trimesh(cube([0, 0, 0], [2, 1, 1]) + cube([0, 0, 1], [1, 1, 2])), 2),
    "U": (lambda: _to_trimesh(cube([0, 0, 0], [3, 1, 3]) - cube([1, -1, 1], [2, 2, 4])), 3),
    "hole": (lambda: _to_trimesh(cube([0, 0, 0], [3, 3, 1]) - cube([1, 1, -1], [2, 2, 2])), 4),
    "stairs": (
        lambda: _to_trimesh(
            cube([0, 0, 0], [3, 1, 1]) + cube([0, 0, 1], [2, 1, 2]) + cube([0, 0, 2], [1, 1, 3])
        ),
        3,
    ),
}


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_decomposition_piece_count_and_exact(shape):
    make, expected = SHAPES[shape]
    mesh = make()
    obj = build_object("obj", mesh, use_cache=False)
    assert len(obj.pieces) == expected
    assert not obj.approximate
    assert sum(p.volume for p in obj.pieces) == pytest.approx(mesh.volume, rel=1e-12)
    exposed = sum(f.exposed_area for p in obj.pieces for f in p.faces)
    assert exposed == pytest.approx(mesh.area, rel=1e-9)
    for p in obj.pieces:  # every piece is convex: all its vertices inside all its half-spaces
        assert (p.vertices @ p.normals.T - p.offsets <= 1e-12).all()
        for f in p.faces:
            assert (f.label == "internal") == (f.face is None)


def test_decomposition_cached(tmp_path):
    mesh = SHAPES["hole"][0]()
    pieces, approx = decompose(mesh)
    assert list((tmp_path / "cache").glob("decomp-*.npz"))
    again, approx2 = decompose(mesh)
    assert approx == approx2 is False
    assert all(np.array_equal(a, b) for a, b in zip(pieces, again, strict=True))


def test_non_polyhedral_mesh_falls_back_to_approximate(monkeypatch):
    import dlovr.geometry.decomposition as geo

    monkeypatch.setattr(geo, "MAX_EXACT_FACES", 10)
    sphere = trimesh.creation.icosphere(subdivisions=1, radius=0.1)
    obj = build_object("ball", sphere, use_cache=False)
    assert obj.approximate and all(p.approximate for p in obj.pieces)


def test_face_names_stable_across_loads_and_poses():
    mesh = SHAPES["hole"][0]()
    a = object_faces(mesh)
    b = object_faces(trimesh.Trimesh(mesh.vertices, mesh.faces[::-1].copy()))  # other triangle order
    assert [(f.index, tuple(np.round(f.normal, 9)), round(f.offset, 9)) for f in a] == [
        (f.index, tuple(np.round(f.normal, 9)), round(f.offset, 9)) for f in b
    ]
    pose = pose_matrix([0.3, -1.0, 2.0], [math.cos(0.4), 0.3 * math.sin(0.4), -0.5, 0.8])
    o1 = build_object("blk", mesh, use_cache=False)
    o2 = build_object("blk", mesh, pose, use_cache=False)
    assert o1.face_names == o2.face_names
    assert np.allclose(o1.face_areas, o2.face_areas)
    assert np.allclose(o1.face_normals @ pose[:3, :3].T, o2.face_normals)
    # the same face gets the same name on the rotated copy's pieces
    for p1, p2 in zip(o1.pieces, o2.pieces, strict=True):
        assert sorted(str(f.face) for f in p1.faces) == sorted(str(f.face) for f in p2.faces)


def test_face_names_top_first_and_split_faces_share_names():
    obj = build_object("lb", SHAPES["L"][0](), use_cache=False)
    assert obj.face_names[0] == "lb.F1" and np.allclose(obj.face_normals[0], [0, 0, 1])
    # the L's foot top lies on one piece as a mixed or external face, and the side x=0 is split over
    # both pieces: both carry the same name
    side = obj.face_names[int(np.argmin(obj.face_normals[:, 0]))]
    assert sum(f.face == side for p in obj.pieces for f in p.faces) == 2


# --------------------------------------------------------------------------------------------------
# Point classification
# --------------------------------------------------------------------------------------------------


def _box_geom(r=0.005):
    # box [0,1]x[0,1]x[0,1]
    return SceneGeometry.from_meshes(
        {"b": (box_mesh([1, 1, 1]), pose_matrix([0.5, 0.5, 0.5], [1, 0, 0, 0]))}, r
    )


def _names_by_normal(geom, obj):
    o = geom.object(obj)
    return {
        tuple(np.round(n).astype(int)): name for n, name in zip(o.face_normals, o.face_names, strict=True)
    }


def test_point_classification_face_edge_vertex():
    r = 0.005
    g = _box_geom(r)
    nm = _names_by_normal(g, "b")
    top, px, py = nm[(0, 0, 1)], nm[(1, 0, 0)], nm[(0, 1, 0)]
    pts = np.array(
        [
            [0.5, 0.5, 1 + r],  # above a face
            [0.9, 0.5, 1 + r],  # above the face, 0.1 from the edge
            [1 + r / 2, 0.5, 1 + r / 2],  # above the edge (in its Voronoi wedge)
            [1 + r / 2, 1 + r / 2, 1 + r / 2],  # at the vertex
            [1 - 0.1 * r, 0.5, 1 + r],  # on the face within the tangential tolerance of the edge
            [1 - 0.5 * r, 0.5, 1 + r],  # on the face beyond the tangential tolerance (r/5)
            [0.5, 0.5, 1 + 3 * r],  # too far away
            [0.5, 0.5, 1 - r],  # penetrating: nearest face
        ]
    )
    hits = g.point_primitives(pts)
    assert [[e.faces for e in h] for h in hits] == [
        [(top,)],
        [(top,)],
        [tuple(sorted((top, px)))],
        [tuple(sorted((top, px, py), key=lambda s: int(s.split("F")[1])))],
        [tuple(sorted((top, px)))],
        [(top,)],
        [],
        [(top,)],
    ]
    det = g.classify_points(pts[:3])
    assert det[0].distance == pytest.approx(r)
    assert np.allclose(det[0].closest, [0.5, 0.5, 1])
    assert det[2].distance == pytest.approx(r / math.sqrt(2))


def test_internal_faces_never_reported():
    r = 0.01
    mesh = SHAPES["hole"][0]()
    g = SceneGeometry.from_meshes({"h": mesh}, r)
    o = g.object("h")
    internal = [f for p in o.pieces for f in p.faces if f.label == "internal"]
    assert internal  # the through hole needs cuts
    rng = np.random.default_rng(1)
    pts = rng.uniform(-0.05, 3.05, size=(4000, 3))
    pts[:, 2] = rng.uniform(-0.05, 1.05, size=4000)
    hits = g.classify_points(pts)
    assert hits
    for h in hits:
        assert set(h.faces) <= set(o.face_names)
    # on the top face right above a cut between two pieces, a point touches only the top face
    top = o.face_names[0]
    cut_x = sorted(
        {
            round(float(f.offset * f.normal[0]), 9)
            for p in o.pieces
            for f in p.faces
            if f.label == "internal" and abs(f.normal[0]) > 0.99
        }
    )
    x = cut_x[0] if cut_x else 1.0
    prims = g.point_primitives(np.array([[x, 0.5, 1 + r], [x, 0.5, 1 + r * 1.01]]))
    for p in prims:
        assert {e.faces for e in p} == {(top,)}


# --------------------------------------------------------------------------------------------------
# Concave / convex and opening angle
# --------------------------------------------------------------------------------------------------


def crease_profile(phi_deg: float) -> list[tuple[float, float]]:
    """(x, z) profile whose top has a crease at the origin with free-space opening angle phi."""
    psi = math.radians(180.0 - phi_deg)
    rx, rz = 0.1 * math.cos(psi), 0.1 * math.sin(psi)
    xr = rx + 0.05
    return [(-0.1, -0.15), (xr, -0.15), (xr, rz), (rx, rz), (0.0, 0.0), (-0.1, 0.0)]


def crease_objects(phi_deg: float, split: bool) -> SceneGeometry:
    mesh = prism_mesh(crease_profile(phi_deg), 0.2)
    if not split:
        return SceneGeometry.from_meshes({"w": mesh}, 0.005)
    psi = math.radians(180.0 - phi_deg)
    b = np.array([-1.0 + math.cos(psi), 0.0, math.sin(psi)])
    if np.linalg.norm(b) < 1e-9:
        b = np.array([0.0, 0.0, 1.0])
    b /= np.linalg.norm(b)
    normal = np.array([b[2], 0.0, -b[0]])
    man = M.Manifold(M.Mesh64(vert_properties=mesh.vertices, tri_verts=mesh.faces.astype(np.uint64)))
    a, c = man.split_by_plane(list(normal), 0.0)
    return SceneGeometry.from_meshes({"a": _to_trimesh(a), "c": _to_trimesh(c)}, 0.005)


def _face_with_normal(g: SceneGeometry, n, through_origin: bool = False) -> str:
    for o in g.objects:
        for name, m, d in zip(o.face_names, o.face_normals, o.face_offsets, strict=True):
            if np.allclose(m, n, atol=1e-9) and (not through_origin or abs(d) < 1e-9):
                return name
    raise AssertionError(f"no face with normal {n}")


@pytest.mark.parametrize("phi", [90.0, 175.0, 179.9, 185.0, 270.0])
@pytest.mark.parametrize("split", [False, True], ids=["one-object", "two-objects"])
def test_concave_convex_and_opening_angle(phi, split):
    g = crease_objects(phi, split)
    psi = math.radians(180.0 - phi)
    left = _face_with_normal(g, [0, 0, 1], True)
    right = _face_with_normal(g, [-math.sin(psi), 0.0, math.cos(psi)], True)
    if split:
        assert left.split(".")[0] != right.split(".")[0]
    else:
        assert left.split(".")[0] == right.split(".")[0]
        e = next(e for e in g.objects[0].edges if {e.a, e.b} == {left, right})
        assert e.convex == (phi > 180) and e.opening_deg == pytest.approx(phi, abs=1e-6)
    pf = g.pair_fact(left, right)
    assert pf.concave == (phi < 180)
    assert pf.opening_deg == pytest.approx(phi, abs=1e-6)
    assert pf.crease is not None and abs(pf.crease[1]) == pytest.approx(1.0)


def test_covered_face_not_counted():
    # a box standing on a table: its bottom is covered, so the bottom edge is no contact edge
    r = 0.005
    g = SceneGeometry.from_meshes(
        {
            "table": (box_mesh([1, 1, 0.1]), pose_matrix([0, 0, -0.05], [1, 0, 0, 0])),
            "box": (box_mesh([0.2, 0.2, 0.2]), pose_matrix([0, 0, 0.1], [1, 0, 0, 0])),
        },
        r,
    )
    side = _names_by_normal(g, "box")[(1, 0, 0)]
    table_top = _names_by_normal(g, "table")[(0, 0, 1)]
    # a cable point in the groove, within the tangential tolerance of the box's bottom edge
    prims = g.point_primitives(np.array([[0.1 + r * 0.5, 0.0, r * 0.1]]))[0]
    names = {f for e in prims for f in e.faces}
    assert names == {side, table_top}
    pf = g.pair_fact(table_top, side)
    assert pf.concave and pf.opening_deg == pytest.approx(90.0)


def test_edge_table_of_l_block():
    obj = build_object("lb", SHAPES["L"][0](), use_cache=False)
    concave = [e for e in obj.edges if not e.convex]
    assert len(concave) == 1 and concave[0].opening_deg == pytest.approx(90.0)
    assert all(e.opening_deg == pytest.approx(270.0) for e in obj.edges if e.convex)
