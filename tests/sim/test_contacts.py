"""Per-step contact extraction (dlovr.sim.tracker): hysteresis, the pair fast path, forces, debouncing.

Pure: a SceneGeometry built from meshes and synthetic simulator records, no MuJoCo.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import manifold3d as M
import numpy as np
import pytest

from dlovr.geometry import SceneGeometry, box_mesh
from dlovr.geometry.mesh import _to_trimesh
from dlovr.sim.tracker import ContactTracker
from dlovr.transforms import pose_matrix

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
              enumerate([0.8, 0.4, 0.8, 0.95, 1.1, 0.8])]
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


def _line(a, b, n=21):
    return np.linspace(a, b, n)


RIDGE_TIP = _line([0.0, 0.125, 0.2], [0.3 + 0.6 * R, 0.125, 0.1 + 0.6 * R])  # tip on the L block's ridge
LANDED_TIP = _line([-0.1, 0.125, 0.2], [0.2, 0.125, 0.1 + 0.9 * R])  # tip pointing into the top face


def flight(tracker, n_free):
    """Tip on a ridge for 40 ms, ``n_free`` steps of 2 ms in the air, then 40 ms on the block's top
    face (the same object: without the flight the step would be a plain S)."""
    up = RIDGE_TIP + np.array([0.0, 0.0, 0.05])
    seq = [RIDGE_TIP] * 20 + [up] * n_free + [LANDED_TIP] * 20
    for k, pts in enumerate(seq):
        tracker.update(Rec(pts, step=k, time=round(k * 0.002, 9)))
    return tracker


def test_the_tracker_classes_a_flight_S_E_and_passes_its_flight_time(geom):
    tr = flight(ContactTracker(geom, hold=0.01), 50)  # 100 ms in the air: within the 0.3 s default
    assert [k.situation.format() for k in tr.kept] == [
        "V/G & E/N & V/E^LI[lblock.F1,lblock.F5]",
        "V/G & E/N & V/F[lblock.F1]",
    ]
    assert [c for _, c in tr.transitions()] == [(), ("S", "E")]
    tr = flight(ContactTracker(geom, hold=0.01, flight=0.05), 50)  # longer than its flight time
    assert [c for _, c in tr.transitions()] == [(), ("S",), ("E",)]
    tr.restart(Rec(RIDGE_TIP))
    assert [c for _, c in flight(tr, 10).transitions()][-1] == ("S", "E")  # 20 ms: a flight again


def _labels(geom, pts, pi, pc, thresholds):
    """Per point: its hits as (piece id, faces, side of every threshold)."""
    pt, pid, dist, faces, _ = geom.pair_hits(pts, pi, pc, contact_tol=1e-3)
    out = {i: [] for i in range(len(pts))}
    for k in range(len(pt)):
        out[int(pt[k])].append((int(pid[k]), faces[k], tuple(bool(dist[k] <= t) for t in thresholds)))
    return out


def test_label_slack_bounds_how_far_a_point_keeps_its_labels(geom):
    rng = np.random.default_rng(7)
    # just above the table, around the L block's edges, corners and (mixed) faces, and within reach of
    # its edges (where the faces of edges within the tangential tolerance count)
    a = np.concatenate([p.edge_a for p in geom.pieces if p.obj == "lblock"])
    b = np.concatenate([p.edge_b for p in geom.pieces if p.obj == "lblock"])
    k = rng.integers(0, len(a), 400)
    on_edges = a[k] + rng.uniform(0, 1, (400, 1)) * (b[k] - a[k])
    off = rng.normal(size=(400, 3))
    off *= rng.uniform(0, R + 2e-3, (400, 1)) / np.linalg.norm(off, axis=1)[:, None]
    pts = np.concatenate(
        [
            rng.uniform([-0.4, -0.4, R - 1e-3], [0.4, 0.4, R + 1.5e-3], (200, 3)),
            rng.uniform([0.08, 0.08, -0.002], [0.32, 0.32, 0.11], (400, 3)),
            on_edges + off,
        ]
    )
    n_pieces = len(geom.pieces)
    pi = np.repeat(np.arange(len(pts)), n_pieces)
    pc = np.tile(np.arange(n_pieces), len(pts))
    thresholds = (R + 5e-4, R + 1e-3)
    slack = geom.label_slack(pts, pi, pc, contact_tol=1e-3, thresholds=thresholds)
    assert slack.shape == (len(pts),) and (slack >= 0).all()
    assert np.median(slack[:200]) > 1e-4  # above the table's face: a real margin, not 0
    before = _labels(geom, pts, pi, pc, thresholds)
    moved_labels = 0
    for _ in range(6):  # every point moved by 99.9% of its slack in a random direction
        u = rng.normal(size=pts.shape)
        u /= np.linalg.norm(u, axis=1)[:, None]
        moved = pts + u * (0.999 * np.where(np.isfinite(slack), slack, 0.0))[:, None]
        assert _labels(geom, moved, pi, pc, thresholds) == before
        far = pts + u * (3.0 * slack + 1e-4)[:, None]  # beyond the slack labels do change somewhere
        moved_labels += sum(
            a != b
            for a, b in zip(before.values(), _labels(geom, far, pi, pc, thresholds).values(), strict=True)
        )
    assert moved_labels > 0


def test_label_slack_over_a_mixed_face_queried_alone(geom):
    """Over a piece face that is only partly the object's surface (the rest is glued to the other
    piece), labels change where the exposed part ends: the slack must see that even when only this
    piece is queried."""
    rng = np.random.default_rng(11)
    (k, pf), *_ = [(k, f) for k, p in enumerate(geom.pieces) for f in p.faces if f.label == "mixed"]
    verts = geom.pieces[k].vertices
    on_plane = np.abs(verts @ pf.normal - pf.offset) < 1e-9
    lo, hi = verts[on_plane].min(axis=0), verts[on_plane].max(axis=0)
    pts = rng.uniform(lo, hi, (600, 3)) + pf.normal * rng.uniform(R - 1e-3, R + 1.5e-3, (600, 1))
    pi, pc = np.arange(len(pts)), np.full(len(pts), k)
    thresholds = (R + 5e-4, R + 1e-3)
    slack = geom.label_slack(pts, pi, pc, contact_tol=1e-3, thresholds=thresholds)
    before = _labels(geom, pts, pi, pc, thresholds)
    assert 0 < sum(bool(v) for v in before.values()) < len(pts)  # some over the exposed part only
    for _ in range(6):
        u = rng.normal(size=pts.shape)
        u /= np.linalg.norm(u, axis=1)[:, None]
        moved = pts + u * (0.999 * np.where(np.isfinite(slack), slack, 0.0))[:, None]
        assert _labels(geom, moved, pi, pc, thresholds) == before


def test_label_budgets_bound_moves_along_and_across_the_faces(geom):
    """Per pair, a move under its budget along the nearest face's normal, across it and in all keeps
    the labels, though it goes far beyond the point's slack in some directions (sliding on a face)."""
    rng = np.random.default_rng(5)
    a = np.concatenate([p.edge_a for p in geom.pieces if p.obj == "lblock"])
    b = np.concatenate([p.edge_b for p in geom.pieces if p.obj == "lblock"])
    k = rng.integers(0, len(a), 300)
    off = rng.normal(size=(300, 3))
    off *= rng.uniform(0, R + 2e-3, (300, 1)) / np.linalg.norm(off, axis=1)[:, None]
    pts = np.concatenate(
        [
            rng.uniform([-0.4, -0.4, R - 1e-3], [0.4, 0.4, R + 1.5e-3], (300, 3)),  # over the table
            rng.uniform([0.08, 0.08, -0.002], [0.32, 0.32, 0.11], (300, 3)),  # around the L block
            a[k] + rng.uniform(0, 1, (300, 1)) * (b[k] - a[k]) + off,  # near its edges
        ]
    )
    n_pieces = len(geom.pieces)
    pi = np.repeat(np.arange(len(pts)), n_pieces)
    pc = np.tile(np.arange(n_pieces), len(pts))
    thresholds = (R + 5e-4, R + 1e-3)
    budgets = geom.pair_hits_and_slack(pts, pi, pc, contact_tol=1e-3, thresholds=thresholds)[6]
    slack = geom.label_slack(pts, pi, pc, contact_tol=1e-3, thresholds=thresholds)
    # the slack is the budgets' smallest, per point
    least = np.minimum(np.minimum(budgets.along, budgets.across), budgets.any)
    per_point = np.full(len(pts), np.inf)
    np.minimum.at(per_point, pi, least)
    assert np.array_equal(per_point, slack)
    before = _labels(geom, pts, pi, pc, thresholds)
    beyond = 0
    for _ in range(6):  # each point moved in a random direction as far as all its pairs' budgets allow
        u = rng.normal(size=pts.shape)
        u /= np.linalg.norm(u, axis=1)[:, None]
        un = np.abs(np.einsum("ij,ij->i", u[pi], budgets.normal))
        ut = np.sqrt(np.maximum(1.0 - un**2, 0.0))
        with np.errstate(divide="ignore"):
            reach = np.minimum(np.minimum(budgets.along / un, budgets.across / ut), budgets.any)
        step = np.full(len(pts), np.inf)
        np.minimum.at(step, pi, reach)
        step = 0.999 * np.where(np.isfinite(step), step, 0.0)
        moved = pts + u * step[:, None]
        some = step[pi] > 0  # a zero budget (a point inside a piece) keeps nothing, not even no move
        assert budgets.keeps(np.arange(len(pi)), (moved - pts)[pi])[some].all()
        assert _labels(geom, moved, pi, pc, thresholds) == before
        beyond += int((step > 2.0 * slack).sum())
    assert beyond > 300  # many moves went well past the slack


def test_label_slack_of_a_point_over_a_face_is_its_distance_to_the_thresholds(geom):
    table = next(k for k, p in enumerate(geom.pieces) if p.obj == "table")
    pts = np.array([[-0.3, -0.3, R + 2e-4]])  # 0.2 mm above contact, far from every edge
    slack = geom.label_slack(pts, np.array([0]), np.array([table]), 1e-3, thresholds=(R + 5e-4, R + 1e-3))
    assert slack[0] == pytest.approx(3e-4)


def test_label_reuse_gives_the_states_of_labelling_every_step(geom):
    """A cable sliding over the table into the L block's side and wobbling in height, its pairs
    reported as a simulator would: the tracker that reuses labels yields exactly the states of one
    that labels every step, while labelling far less often."""
    fast, full = ContactTracker(geom, hold=0.01), ContactTracker(geom, hold=0.01, reuse=False)
    rng = np.random.default_rng(3)
    block = [k for k, p in enumerate(geom.pieces) if p.obj == "lblock"]
    for k in range(500):
        pts = cable(R + 1.5e-3 * np.sin(k / 15.0), x0=-0.23 + 1e-4 * k) + rng.normal(0, 2e-6, (21, 3))
        pts[:, 1] = 0.2
        low = np.nonzero(pts[:, 2] < R + 1e-3)[0]
        ahead = np.nonzero(pts[:, 0] > 0.09)[0]
        rows = [arrays(low, geom, force=0.05)] + [
            arrays(ahead, geom, piece=geom.pieces[b].index, obj=1) for b in block
        ]
        rec = Rec(pts, step=k, time=0.002 * k, contact_arrays=_stack(rows))
        a, b = fast.update(rec), full.update(rec)
        assert (a.topological, a.discrete, a.forces) == (b.topological, b.discrete, b.forces), k
    assert fast.changes == full.changes and fast.kept == full.kept
    assert len(fast.changes) > 6 and any("lblock" in c.discrete.format() for c in fast.changes)
    assert full.labellings == 500 and fast.labellings < 250


def _stack(parts):
    return SimpleNamespace(
        **{
            k: np.concatenate([getattr(p, k) for p in parts])
            for k in ("point", "segment", "geom", "obj", "piece", "dist", "normal", "pos", "force", "active")
        },
        names=parts[0].names,
    )


def _leaning(deg, n=21, length=0.3):
    """A straight cable from the gripper down to its tip on the table, meeting it at ``deg``."""
    a = np.radians(deg)
    tip = np.array([0.0, -0.3, R + 2e-4])
    top = tip + length * np.array([-np.cos(a), 0.0, np.sin(a)])
    return _line(top, tip, n)


def test_the_tip_angle_has_hysteresis(geom):
    """docs/model.md section 2: a touching tip holds until the angle is the band below the tip angle
    (15 - 3 = 12 deg); a tip that does not touch must pass 15 deg again."""
    tip, lying = "V/G & E/N & V/F[table.F1]", "V/G & E/N & E/F[table.F1] & V/N"
    angles = [17, 13.5, 11, 13.5, 16, 13.5]

    def states(tr):
        return [tr.update(Rec(_leaning(d), step=k, time=k * 0.002)).discrete.format()
                for k, d in enumerate(angles)]

    assert states(ContactTracker(geom)) == [tip, tip, lying, lying, tip, tip]
    assert states(ContactTracker(geom, tip_band_deg=0.0)) == [tip, lying, lying, lying, tip, lying]


def test_a_refreshed_situation_is_the_one_made_from_the_points_again():
    """When the kept hits change but no point's primitives do, the tracker refreshes the last
    situation's DLO vectors and gripper z instead of contracting every point again: the very objects
    ``situation_from_points`` makes, annotations included (vectors, spans, indices, G's z)."""
    from dlovr.model.topology import EnvPrimitive, situation_from_points
    from dlovr.sim.tracker import _plan, _refreshed

    floor, wall = EnvPrimitive("faces", ("table.F1",)), EnvPrimitive("faces", ("wall.F2",))
    edge = EnvPrimitive("faces", ("wall.F1", "wall.F2"))
    env = [[], [floor], [floor], [floor, wall], [floor, wall], [edge], [], [], [floor]]
    normals = {"table.F1": [0.0, 0.0, 1.0], "wall.F1": [0.0, 0.0, 1.0], "wall.F2": [1.0, 0.0, 0.0]}

    def ann(s):
        return [(c.dlo.kind, c.dlo.index, c.dlo.span, c.dlo.vector, c.env, [e.z for e in c.env])
                for c in s.contacts]

    rng = np.random.default_rng(5)
    pts = cable(R, n=len(env))
    first = situation_from_points(env, pts[1:] - pts[:-1], normals.__getitem__, gripper_z=(0.0, 0.0, 1.0))
    for _ in range(20):
        moved = pts + rng.normal(0.0, 1e-4, pts.shape)
        zx, zy, zz = (float(x) for x in rng.normal(0.0, 1.0, 3))
        z = (zx, zy, zz)
        want = situation_from_points(env, moved[1:] - moved[:-1], normals.__getitem__, gripper_z=z)
        got = _refreshed(first, moved, z, _plan(first, len(moved) - 1))
        assert got == want and ann(got) == ann(want)
        assert got.format() == want.format()


def _across_ridge(deg, n=31, length=0.3):
    """A straight cable touching the L block's ridge along x (top face and -y face, y 0.1, z 0.1) at
    x 0.2 and nothing else, ``deg`` from the ridge (turned in the plane of the ridge and the
    direction that leaves both faces)."""
    a = np.radians(deg)
    b, w = np.array([0.0, -1.0, 1.0]) / np.sqrt(2.0), np.array([0.0, 1.0, 1.0]) / np.sqrt(2.0)
    d = np.cos(a) * np.array([1.0, 0.0, 0.0]) + np.sin(a) * w
    mid = np.array([0.2, 0.1, 0.1]) + (R + 2e-4) * b
    return _line(mid - 0.5 * length * d, mid + 0.5 * length * d, n)


def test_the_point_or_line_decision_has_hysteresis(geom):
    """docs/model.md section 3.2: a line contact on an edge holds until the DLO vector is the band
    beyond the parallel tolerance (10 + 3 = 13 deg); a point contact must come within 10 deg again."""
    angles = [5, 11.5, 12.5, 14, 11.5, 8]

    def states(tr):
        out = []
        for k, d in enumerate(angles):
            c = [x for x in tr.update(Rec(_across_ridge(d), step=k, time=k * 0.002)).discrete.contacts
                 if x.faces]
            assert len(c) == 1 and c[0].faces == ("lblock.F1", "lblock.F7"), c
            out.append(c[0].state.name)
        return out

    line, point = "E/E^LI", "E/E^P"
    assert states(ContactTracker(geom)) == [line, line, line, point, point, line]
    assert states(ContactTracker(geom, line_band_deg=0.0)) == [line, point, point, point, point, line]
    tr = ContactTracker(geom)
    tr.update(Rec(_across_ridge(5), step=0, time=0.0))
    assert tr.restart(Rec(_across_ridge(11.5), step=1, time=0.002)).discrete.contacts[2].state.name == point
