"""Per-step contact extraction (dlovr.contacts): hysteresis, the pair fast path, forces, debouncing.

Pure: a SceneGeometry built from meshes and synthetic simulator records, no MuJoCo.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import manifold3d as M
import numpy as np
import pytest

from dlovr.contacts import ContactTracker
from dlovr.geometry import SceneGeometry, _to_trimesh, box_mesh, pose_matrix

R = 0.005


@pytest.fixture(scope="module")
def geom() -> SceneGeometry:
    table = (box_mesh([1.0, 1.0, 0.05]), pose_matrix([0, 0, -0.025], [1, 0, 0, 0]))
    lblock = _to_trimesh(
        M.Manifold.cube([0.2, 0.05, 0.1]).translate([0.1, 0.1, 0.0])
        + M.Manifold.cube([0.05, 0.2, 0.1]).translate([0.1, 0.1, 0.0])
    )
    return SceneGeometry.from_meshes({"table": table, "lblock": lblock}, radius=R)


@dataclass
class Rec:
    """A synthetic simulator step: points along x at height z, optional contact arrays."""

    points: np.ndarray
    step: int = 0
    time: float = 0.0
    gripper_z: tuple = (0.0, 0.0, 1.0)
    gripper_pos: tuple = (0.0, 0.0, 0.0)
    gripper_quat: tuple = (1.0, 0.0, 0.0, 0.0)
    contact_arrays: object = field(default=None)


def cable(z, n=21, x0=-0.4, length=0.3):
    pts = np.zeros((n, 3))
    pts[:, 0] = x0 + np.linspace(0.0, length, n)
    pts[:, 1] = -0.3
    pts[:, 2] = z
    pts[:3, 2] += [0.05, 0.03, 0.01]  # held up by the gripper
    return pts


def arrays(points_idx, geom, piece=0, obj=0, force=0.0):
    k = len(points_idx)
    return SimpleNamespace(
        point=np.asarray(points_idx, int),
        segment=np.full(k, -1),
        geom=np.full(k, 1),
        obj=np.full(k, obj),
        piece=np.full(k, piece),
        dist=np.zeros(k),
        normal=np.tile([0.0, 0.0, 1.0], (k, 1)),
        pos=np.zeros((k, 3)),
        force=np.full(k, force),
        active=np.ones(k, bool),
        names=(("table", "lblock"), {1: "table.P0"}),
    )


def test_tracker_on_a_static_polyline_matches_the_geometry(geom):
    tr = ContactTracker(geom, hold=0.01)
    pts = cable(R)
    st = tr.update(Rec(pts))
    assert st.topological == geom.situation(pts)
    assert st.discrete.format() == "V/G & E/N & E/F[table.F1] & V/N"


def test_hysteresis_enter_below_half_a_millimetre_leave_beyond_one(geom):
    tr = ContactTracker(geom, enter_tol=5e-4, leave_tol=1e-3)
    states = [tr.update(Rec(cable(R + gap_mm * 1e-3), step=k)).discrete.format() for k, gap_mm in
              enumerate([0.8, 0.4, 0.8, 0.95, 1.1, 0.8])]  # fmt: skip
    free, lying = "V/G & E/N & V/N", "V/G & E/N & E/F[table.F1] & V/N"
    assert states == [free, lying, lying, lying, free, free]


def test_pair_fast_path_agrees_with_the_full_classifier(geom):
    rng = np.random.default_rng(1)
    # points around the L block's edges, corners and faces and on the table, all pieces
    pts = np.concatenate(
        [
            rng.uniform([0.08, 0.08, -0.002], [0.32, 0.32, 0.11], (400, 3)),
            rng.uniform([-0.4, -0.4, R - 1e-3], [0.4, 0.4, R + 1.5e-3], (200, 3)),
        ]
    )
    n_pieces = len(geom.pieces)
    pi = np.repeat(np.arange(len(pts)), n_pieces)
    pc = np.tile(np.arange(n_pieces), len(pts))
    pt, pid, dist, faces, _ = geom.pair_hits(pts, pi, pc, contact_tol=1e-3)
    full = geom.classify_points(pts, contact_tol=1e-3)
    fast = [
        (
            int(pt[i]),
            geom.pieces[int(pid[i])].obj,
            geom.pieces[int(pid[i])].index,
            faces[i],
            round(float(dist[i]), 9),
        )
        for i in range(len(pt))
    ]
    assert sorted(fast) == sorted(
        (h.point, h.piece.obj, h.piece.index, h.faces, round(h.distance, 9)) for h in full
    )
    assert len(full) > 100 and any(len(h.faces) > 1 for h in full)


def test_forces_are_summed_over_each_contact_span(geom):
    tr = ContactTracker(geom)
    pts = cable(R)
    st = tr.update(Rec(pts, contact_arrays=arrays(range(5, 20), geom, force=0.1)))
    by = dict(zip([c.format() for c in st.topological.contacts], st.forces, strict=True))
    lying = next(k for k in by if "table.F1" in k)
    assert by[lying] == pytest.approx(0.1 * 15) and sum(st.forces) == pytest.approx(1.5)
    payload = st.payload(("E",))
    assert payload["classes"] == ["E"] and payload["contacts"][2]["vector"] == [0.0, 0.0, -1.0]


def test_only_reported_pairs_are_classified(geom):
    tr = ContactTracker(geom)
    pts = cable(R)
    st = tr.update(Rec(pts, contact_arrays=arrays([], geom)))  # the simulator reports nothing
    assert st.discrete.format() == "V/G & E/N & V/N"
    st = tr.update(Rec(pts, step=1, contact_arrays=arrays([7, 8, 9], geom)))
    assert [c.dlo.span for c in st.topological.contacts if c.touches_environment] == [(7, 9)]


def test_changes_and_debounced_kept_situations(geom):
    tr = ContactTracker(geom, hold=0.01)
    seq = [R + 3e-3] * 20 + [R] * 2 + [R + 3e-3] * 20 + [R] * 30  # a 4 ms touch (flicker), then lying
    for k, z in enumerate(seq):
        tr.update(Rec(cable(z), step=k, time=k * 0.002))
    assert [c.discrete.format() for c in tr.changes] == [
        "V/G & E/N & V/N",
        "V/G & E/N & E/F[table.F1] & V/N",
        "V/G & E/N & V/N",
        "V/G & E/N & E/F[table.F1] & V/N",
    ]
    assert [k.situation.format() for k in tr.kept] == ["V/G & E/N & V/N", "V/G & E/N & E/F[table.F1] & V/N"]
    assert [c for _, c in tr.transitions()] == [(), ("E",)]
    st = tr.restart(Rec(cable(R), step=100, time=0.2))
    assert tr.changes == [st] and len(tr.kept) == 1
