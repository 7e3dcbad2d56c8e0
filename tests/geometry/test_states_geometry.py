# ruff: noqa: RUF005  (numpy array + list is vector addition here, not list concatenation)
"""End-to-end: each of the 15 discrete states from a hand-placed static cable polyline in a scene,
classified through geometry (dlovr.geometry) and the model (dlovr.model.discrete)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from dlovr.geometry import SceneGeometry, box_mesh, prism_mesh
from dlovr.model.discrete import STATES
from dlovr.transforms import pose_matrix

R = 0.005
S5, C5 = math.sin(math.radians(5)), math.cos(math.radians(5))
ID = [1, 0, 0, 0]


@pytest.fixture(scope="module")
def geom(tmp_path_factory) -> Iterator[SceneGeometry]:
    mp = pytest.MonkeyPatch()
    mp.setenv("DLOVR_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
    try:
        yield make_geom()
    finally:
        mp.undo()


def make_geom() -> SceneGeometry:
    # table top at z = 0; a box [0,0.2]^2 x [0,0.1]; an L-shaped wall with an inner corner at
    # (0.35, 0.35); a plate whose top bends up by 5 deg (175 deg valley along y at x = -0.25);
    # a wall on the table whose face (normal +y at y = -0.3) bends by 5 deg toward +y at x = -0.2.
    import manifold3d as M

    from dlovr.geometry.mesh import _to_trimesh

    def cube(lo, hi):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        return M.Manifold.cube(list(hi - lo)).translate(list(lo))

    lwall = _to_trimesh(cube([0.3, 0.3, 0], [0.5, 0.35, 0.1]) + cube([0.3, 0.35, 0], [0.35, 0.5, 0.1]))
    L2 = 0.1
    plate = prism_mesh(
        [(-0.15, 0.0), (L2 * C5, 0.0), (L2 * C5, 0.02 + L2 * S5), (0.0, 0.02), (-0.15, 0.02)], 0.3
    )
    # bent wall: profile in (x, y), extruded along z: build as a prism along y, then rotate y -> z
    prof = [
        (-0.4, -0.35),
        (-0.2 + 0.15 * C5, -0.35),
        (-0.2 + 0.15 * C5, -0.3 + 0.15 * S5),
        (-0.2, -0.3),
        (-0.4, -0.3),
    ]
    bent = prism_mesh([(x, -y) for x, y in prof][::-1], 0.1)  # (x, z=-y) profile, CCW after the flip
    # rotate +90 deg about x: (x, y, z) -> (x, -z, y); the prism's y in [-0.05, 0.05] becomes z
    rot = np.eye(4)
    rot[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    bent.apply_transform(rot)
    bent.apply_translation([0, 0, 0.05])
    return SceneGeometry.from_meshes(
        {
            "table": (box_mesh([1.2, 1.2, 0.05]), pose_matrix([0, 0, -0.025], ID)),
            "box": (box_mesh([0.2, 0.2, 0.1]), pose_matrix([0.1, 0.1, 0.05], ID)),
            "lwall": lwall,
            "plate": (plate, pose_matrix([-0.25, 0.2, 0.0], ID)),
            "bent": bent,
        },
        R,
    )


def corner_point(c, normals, r=R):
    """Point at distance r from every plane through c with these (outward) normals (2 or 3)."""
    n = np.asarray(normals, float)
    if len(n) == 2:
        return np.asarray(c, float) + r * (n[0] + n[1]) / (1 + n[0] @ n[1])
    return np.asarray(c, float) + np.linalg.solve(n, np.full(3, r))


def line(a, b, k):
    return np.linspace(np.asarray(a, float), np.asarray(b, float), k)


UP = np.array([0.0, 0.0, 1.0])
NY5 = np.array([-S5, C5, 0.0])  # bent wall, second part
NZ5 = np.array([-S5, 0.0, C5])  # plate, rising part


def polylines() -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    g0 = [-0.3, 0.0, 0.3]  # the gripper, above the table
    # E/F: lying on the table
    out["E/F"] = np.vstack([[-0.45, -0.05, 0.2], line([-0.45, 0.0, R], [-0.45, 0.15, R], 8)])
    # E/E^P: draped over the box's top edge at x = 0.2 (an arc of radius R around it)
    th = np.linspace(0.0, math.pi / 2, 7)
    arc = np.column_stack([0.2 + R * np.sin(th), np.full(7, 0.1), 0.1 + R * np.cos(th)])
    out["E/E^P"] = np.vstack(
        [[0.05, 0.1, 0.3], line([0.1, 0.1, 0.1 + R], [0.19, 0.1, 0.1 + R], 4), arc, [0.2 + R, 0.1, 0.05]]
    )
    # E/E^LS: along the groove between the table and the box side x = 0.2
    gr = corner_point([0.2, 0, 0], [UP, [1, 0, 0]])
    out["E/E^LS"] = np.vstack([[0.3, 0.0, 0.3], line(gr + [0, 0.02, 0], gr + [0, 0.18, 0], 9)])
    # E/VS: along the groove (table, lwall y-face) into the corner, then up the vertical groove
    cs = corner_point([0.35, 0.35, 0], [UP, [1, 0, 0], [0, 1, 0]])
    floor = line(cs + [0.12, 0, 0], cs, 7)
    upg = line(cs, cs + [0, 0, 0.06], 4)[1:]
    out["E/VS"] = np.vstack([[0.6, 0.4, 0.3], floor, upg])
    # V/F: tip pressed onto the table
    out["V/F"] = np.vstack([g0, line([-0.3, 0.0, 0.1], [-0.3, 0.0, R], 5)])
    # V/E^LS: tip into the table-box groove, coming diagonally
    gm = gr + [0, 0.1, 0]
    out["V/E^LS"] = np.vstack([gm + [0.2, 0, 0.2], line(gm + [0.05, 0, 0.05], gm, 4)])
    # V/VS: tip into the lwall corner
    out["V/VS"] = np.vstack([cs + [0.2, 0.2, 0.2], line(cs + [0.04, 0.04, 0.04], cs, 4)])
    # E/E^LT: along the 175 deg valley of the plate (crease along y at x = -0.25, z = 0.02)
    pv = corner_point([-0.25, 0.0, 0.02], [UP, NZ5])
    out["E/E^LT"] = np.vstack([pv + [0, 0.0, 0.2], line(pv + [0, 0.1, 0], pv + [0, 0.25, 0], 8)])
    # V/E^LT: tip into that valley from above
    out["V/E^LT"] = np.vstack([pv + [0, 0.2, 0.2], line(pv + [0, 0.2, 0.05], pv + [0, 0.2, 0], 4)])
    # E/VT: along the groove of the table and the bent wall, through the foot of its 175 deg crease
    ct = corner_point([-0.2, -0.3, 0.0], [UP, [0, 1, 0], NY5])
    g1 = corner_point([-0.3, -0.3, 0.0], [UP, [0, 1, 0]])
    d2 = np.array([C5, S5, 0.0])
    g2 = corner_point(np.array([-0.2, -0.3, 0.0]) + 0.1 * d2, [UP, NY5])
    out["E/VT"] = np.vstack([[-0.3, 0.0, 0.3], line(g1, ct, 6), line(ct, g2, 6)[1:]])
    # V/VT: tip into that corner
    out["V/VT"] = np.vstack([ct + [0, 0.2, 0.2], line(ct + [0, 0.04, 0.04], ct, 4)])
    # E/E^LI: balanced along the box's top edge x = 0.2 (a ridge)
    ridge = np.array([0.2, 0.0, 0.1]) + R * np.array([1, 0, 1]) / math.sqrt(2)
    out["E/E^LI"] = np.vstack([[0.2, -0.1, 0.3], line(ridge + [0, 0.03, 0], ridge + [0, 0.17, 0], 8)])
    # E/VI: over the box's top corner (0.2, 0.2, 0.1), diagonally
    cv = np.array([0.2, 0.2, 0.1]) + R * np.ones(3) / math.sqrt(3)
    out["E/VI"] = np.vstack(
        [[0.05, 0.05, 0.3], line([0.1, 0.1, 0.1 + R], [0.17, 0.17, 0.1 + R], 3), cv, [0.25, 0.25, 0.05]]
    )
    # V/E^LI: tip on the box's top edge x = 0.2
    out["V/E^LI"] = np.vstack(
        [ridge + [0.2, 0.1, 0.2], line(ridge + [0.05, 0.1, 0.05], ridge + [0, 0.1, 0], 4)]
    )
    # V/VI: tip on the box's top corner
    out["V/VI"] = np.vstack([cv + [0.2, 0.2, 0.2], line(cv + [0.04, 0.04, 0.04], cv, 4)])
    return out


CASES = polylines()


def test_all_fifteen_states_covered():
    assert set(CASES) == set(STATES)


@pytest.mark.parametrize("name", sorted(CASES))
def test_state_from_polyline(geom, name):
    pts = CASES[name]
    disc = geom.discrete_situation(pts)
    states = [c.state.name for c in disc.contacts]
    assert states[0] == "V/G"
    principal = [c for c in disc.contacts if c.state.is_principal_kind]
    assert name in [c.state.name for c in principal], f"{name}: got {disc}"
    # the state of highest card among the contacts that touch the environment is the expected one
    # for the tip states; for E states no V contact may appear
    if name.startswith("E/"):
        assert states[-1] == "V/N", disc
    else:
        assert states[-1] == name, disc


def test_fact_book_faces_and_lazy_pairs(geom):
    book = geom.fact_book()
    assert all(not f.internal for f in book.faces.values())
    assert "box.F1" in book.faces and "table.F1" in book.faces
    disc = geom.discrete_situation(CASES["E/VS"])
    c = next(c for c in disc.contacts if c.state.name == "E/VS")
    assert len(c.faces) == 3 and {f.split(".")[0] for f in c.faces} == {"table", "lwall"}
    assert c.vector is not None and c.vector[2] < 0
