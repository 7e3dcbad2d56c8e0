"""Per-step contact extraction: a simulation step -> topological and discrete contact situation.

Pure (numpy + the model + geometry; no MuJoCo): it reads the cable points and, when given, the raw
contact arrays of :class:`dlovr.sim.ContactArrays` (to know which points to classify and to attach
normal forces). Contacts are labelled geometrically (NOTES.md): a point touches a piece when its
centerline is within ``radius + enter_tol`` of it, and keeps touching until it is farther than
``radius + leave_tol`` (hysteresis). The per-step situations are debounced (docs/model.md: flicker,
brief intermediate states, flights) into the demonstration's kept situations.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dlovr.geometry import LabelBudgets, SceneGeometry, primitives_per_point
from dlovr.model.discrete import DiscreteSituation, ModelParams, discretize
from dlovr.model.topology import Situation, situation_from_points, tip_touches
from dlovr.model.transitions import (
    DEFAULT_FLIGHT_S,
    DEFAULT_HOLD_S,
    Debouncer,
    Kept,
    is_transient,
    kept_classes,
)


@dataclass(frozen=True)
class ContactState:
    """The contact situation of one step.

    ``forces``: per contact of ``topological`` (same order), the summed normal force (N) of the
    simulator's contacts on that stretch of cable; 0 for free contacts. ``gripper_force``: the force
    (N, world frame) the cable exerts on the gripper; gripper pose in the world frame (quat wxyz).
    """

    step: int
    t: float
    topological: Situation
    discrete: DiscreteSituation
    forces: tuple[float, ...]
    gripper_pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gripper_quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    gripper_force: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def payload(self, classes: Sequence[str] = ()) -> dict[str, Any]:
        """JSON-able form for recordings and the UI."""
        contacts = []
        for tc, dc, f in zip(self.topological.contacts, self.discrete.contacts, self.forces, strict=True):
            contacts.append(
                {
                    "dlo": tc.dlo.format(),
                    "span": list(tc.dlo.span) if tc.dlo.span else None,
                    "state": dc.state.name,
                    "faces": list(dc.faces),
                    "vector": list(dc.vector) if dc.vector is not None else None,
                    "force": f,
                }
            )
        return {
            "t": self.t,
            "step": self.step,
            "topological": self.topological.format(),
            "discrete": self.discrete.format(),
            "classes": list(classes),
            "gripper_pos": list(self.gripper_pos),
            "gripper_quat": list(self.gripper_quat),
            "gripper_force": list(self.gripper_force),
            "contacts": contacts,
        }


@dataclass
class ContactTracker:
    """Turns simulation steps into contact situations, debounced into the demonstration's sequence.

    ``hold`` (s) is the flicker hold time and ``flight`` (s) the flight time of the debouncing
    (docs/model.md, :class:`dlovr.model.transitions.Debouncer`). ``changes`` lists every step at
    which the raw situation changed (what a recording stores); ``kept`` the debounced situations.

    ``reuse``: a step that queries the same (point, piece) pairs as the step of the last labelling,
    with every queried point closer to where it was then than its slack
    (:meth:`dlovr.geometry.SceneGeometry.label_slack`), keeps those labels instead of labelling
    again: the same result, cheaper; points that moved farther are labelled again alone.
    ``labellings`` counts the steps that labelled every queried point, ``partial_labellings`` those
    that labelled some.
    """

    geometry: SceneGeometry
    params: ModelParams = field(default_factory=ModelParams)
    hold: float = DEFAULT_HOLD_S
    flight: float = DEFAULT_FLIGHT_S
    enter_tol: float = 5e-4
    leave_tol: float = 1e-3
    changes: list[ContactState] = field(default_factory=list)
    reuse: bool = True

    def __post_init__(self) -> None:
        self._debouncer: Debouncer[DiscreteSituation] = Debouncer(self.hold, is_transient, self.flight)
        self._touching = np.zeros(0, dtype=np.int64)  # (point << 20 | piece id) in contact
        self._signature: tuple[Any, ...] | None = None
        self._piece_map: tuple[Any, np.ndarray] | None = None
        self._tip: tuple[Any, list[np.ndarray]] | None = None
        self._situation: Situation | None = None
        self._labels: _Labels | None = None
        self._pairs_memo: tuple[np.ndarray, ...] | None = None
        self.labellings = 0
        self.partial_labellings = 0
        self.current: ContactState | None = None

    def restart(self, record: Any) -> ContactState:
        """Forget all history (hysteresis, changes, debouncing) and start again from ``record``.

        A recording starts this way, and its replay too, so both see the same contact states.
        """
        self._debouncer = Debouncer(self.hold, is_transient, self.flight)
        self._touching = np.zeros(0, dtype=np.int64)
        self._signature = self._situation = None
        self._labels = self._pairs_memo = None
        self.changes = []
        self.current = None
        return self.update(record)

    @property
    def kept(self) -> list[Kept[DiscreteSituation]]:
        return self._debouncer.kept

    def classify(
        self,
        points: np.ndarray,
        gripper_z: Sequence[float] | None = None,
        pairs: tuple[np.ndarray, np.ndarray] | None = None,
        between: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> Situation:
        """Topological situation of the cable polyline ``points`` (hysteresis applied).

        ``pairs``: (point indices, piece ids) the simulator reports in contact; only those (and the
        pairs touching at the last step) are classified. ``None``: every point against every piece.
        ``between``: (centerline positions, owner point, piece id) of contacts the simulator reports
        between two points (a segment crossing an edge touches it between its end points); their
        labels count for the nearer point.
        """
        pts = np.asarray(points, dtype=float)
        geom = self.geometry
        if pairs is None:
            pi = np.repeat(np.arange(len(pts)), len(geom.pieces))
            pc = np.tile(np.arange(len(geom.pieces)), len(pts))
        else:  # the reported pairs and those touching at the last step, once each
            raw_pi, raw_pc = (np.asarray(a, dtype=np.int64) for a in pairs)
            memo, touching = self._pairs_memo, self._touching
            if (
                memo is not None
                and _same(raw_pi, memo[0])
                and _same(raw_pc, memo[1])
                and _same(touching, memo[2])
            ):
                pi, pc = memo[3], memo[4]
            else:
                pi, pc = _unique_pairs(
                    np.concatenate([raw_pi, touching >> 20]), np.concatenate([raw_pc, touching & _LOW])
                )
                self._pairs_memo = (raw_pi, raw_pc, touching, pi, pc)
        owner = np.arange(len(pts))
        if between is not None and len(between[0]):
            vpos, vowner, vpiece = between
            pi = np.concatenate([pi, len(pts) + np.arange(len(vpos))])
            pc = np.concatenate([pc, vpiece])
            owner = np.concatenate([owner, vowner])
            pts_all = np.concatenate([pts, vpos])
        else:
            pts_all = pts
        lab = self._reuse_labels(pts_all, pi, pc) or self._label(pts_all, pi, pc)
        kept_hits = self._hits(lab, owner)
        n = len(pts) - 1
        # the labels decide the situation, and the end-vertex rule when the tip has a contact:
        # cache the situation by both
        if self._tip is None or self._tip[0] is not kept_hits:  # the tip's faces, per labelling
            tip_faces = sorted({f for h in kept_hits if h.point == n for f in h.faces})
            normals = [np.asarray(geom.face_normal(f), dtype=float).tolist() for f in tip_faces]
            self._tip = (kept_hits, normals)
        tip_normals = self._tip[1]
        tip = None
        if tip_normals:
            tip = tip_touches((pts[n] - pts[n - 1]).tolist(), tip_normals, self.params.tip_angle_deg)
        signature = (len(pts), tuple(kept_hits), tip)
        if signature == self._signature and self._situation is not None:
            return self._situation
        env = primitives_per_point(len(pts), kept_hits)
        z = tuple(float(x) for x in gripper_z) if gripper_z is not None else (0.0, 0.0, 1.0)
        sit = situation_from_points(
            env,
            np.diff(pts, axis=0),
            self.geometry.face_normal,
            tip_angle_deg=self.params.tip_angle_deg,
            gripper_z=z,  # type: ignore[arg-type]
        )
        self._signature, self._situation = signature, sit
        return sit

    @property
    def _thresholds(self) -> tuple[float, float]:
        """The centerline distances (m) at which a pair enters contact and leaves it."""
        r = self.geometry.radius
        return r + self.enter_tol, r + self.leave_tol

    def _label(self, pts_all: np.ndarray, pi: np.ndarray, pc: np.ndarray) -> _Labels:
        """Label the queried (point, piece) pairs geometrically (which faces each touches, and on which
        side of the enter and leave distances)."""
        self.labellings += 1
        pt, pid, dist, faces, _ = self.geometry.pair_hits(pts_all, pi, pc, contact_tol=self.leave_tol)
        t_enter, t_leave = self._thresholds
        enter, leave = dist <= t_enter, dist <= t_leave
        lab = _Labels(pi, pc, pts_all.copy(), pt, pid, faces, enter, leave, bool((leave & ~enter).any()))
        self._labels = lab
        return lab

    def _hits(self, lab: _Labels, owner: np.ndarray) -> list[_Hit]:
        """The labelled pairs that touch, by cable point, with hysteresis: a pair within the enter
        distance touches, one within the leave distance keeps touching."""
        if lab.owner is not None and not lab.between and _same(owner, lab.owner):
            return lab.hits  # the same owners, no pair between the distances: the same hits
        pt = owner[lab.pt]
        keys = pt << 20 | lab.pid
        keep = lab.enter | (_member(keys, self._touching) & lab.leave)
        self._touching = np.unique(keys[keep])
        if lab.owner is not None and _same(keep, lab.keep) and _same(pt, lab.owner[lab.pt]):
            lab.owner = owner
            return lab.hits
        faces = lab.faces
        lab.hits = [
            _Hit(p, faces[i]) for i, p in zip(np.nonzero(keep)[0].tolist(), pt[keep].tolist(), strict=True)
        ]
        lab.owner, lab.keep = owner, keep
        return lab.hits

    def _reuse_labels(self, pts_all: np.ndarray, pi: np.ndarray, pc: np.ndarray) -> _Labels | None:
        """The last labels when the same pairs are queried, brought up to date: points that moved by
        less than their slack since they were labelled keep their labels (labelling them again would
        give the same), the others are labelled again. ``None`` when the queried pairs changed."""
        lab = self._labels
        if lab is None or not self.reuse or len(pi) != len(lab.pi) or len(pts_all) != len(lab.pts):
            return None
        if not (_same(pi, lab.pi) and _same(pc, lab.pc)):
            return None
        if lab.q is None:
            lab.q = np.unique(lab.pi)
            *_, slack, budgets = self.geometry.pair_hits_and_slack(
                lab.pts, lab.pi, lab.pc, self.leave_tol, thresholds=self._thresholds
            )
            lab.slack2 = slack[lab.q] ** 2
            lab.budgets = _own(budgets)
        if len(lab.q) == 0:
            return lab
        dp = pts_all[lab.q] - lab.pts[lab.q]
        moved = np.einsum("ij,ij->i", dp, dp) >= lab.slack2
        if not moved.any():
            return lab
        # beyond its slack in some direction: within its budgets along and across its faces?
        rows = _member(pi, lab.q[moved])
        moving = pi[rows]
        kept = lab.budgets.keeps(rows, pts_all[moving] - lab.pts[moving])
        if kept.all():
            return lab
        # label the moved points again (a point's labels depend on it alone) and splice them in
        self.partial_labellings += 1
        again = np.unique(moving[~kept])
        rows = _member(pi, again)
        t_enter, t_leave = self._thresholds
        pt, pid, dist, faces, _, slack, budgets = self.geometry.pair_hits_and_slack(
            pts_all, pi[rows], pc[rows], self.leave_tol, thresholds=(t_enter, t_leave)
        )
        old = ~_member(lab.pt, again)
        pt_all = np.concatenate([lab.pt[old], pt])
        pid_all = np.concatenate([lab.pid[old], pid])
        order = np.lexsort((pid_all, pt_all))
        old_faces = [f for f, o in zip(lab.faces, old.tolist(), strict=True) if o]
        all_faces = old_faces + faces
        enter = np.concatenate([lab.enter[old], dist <= t_enter])[order]
        leave = np.concatenate([lab.leave[old], dist <= t_leave])[order]
        lab.pt, lab.pid, lab.enter, lab.leave = pt_all[order], pid_all[order], enter, leave
        lab.faces = [all_faces[i] for i in order.tolist()]
        lab.between = bool((leave & ~enter).any())
        lab.pts[again] = pts_all[again]  # lab.pts and the budgets are the labelling's own
        lab.slack2[_member(lab.q, again)] = slack[again] ** 2
        for mine, new in zip(_fields(lab.budgets), _fields(budgets), strict=True):
            mine[rows] = new
        lab.owner = None  # the hits must be made again
        return lab

    def _piece_ids(self, arrays: Any) -> np.ndarray:
        """Piece ids (positions in ``geometry.pieces``) of the simulator's contacts."""
        objs = arrays.names[0]
        if self._piece_map is None or self._piece_map[0] is not objs:
            pieces = self.geometry.pieces
            table = np.full((max(len(objs), 1), max((p.index for p in pieces), default=0) + 1), -1, np.int64)
            row = {o: i for i, o in enumerate(objs)}
            for k, p in enumerate(pieces):
                if p.obj in row:
                    table[row[p.obj], p.index] = k
            self._piece_map = (objs, table)
        table = self._piece_map[1]
        obj, piece = np.asarray(arrays.obj), np.asarray(arrays.piece)
        ids = table[obj, np.minimum(piece, table.shape[1] - 1)]
        bad = (ids < 0) | (piece >= table.shape[1])
        if bad.any():
            i = int(np.nonzero(bad)[0][0])
            raise KeyError(f"the geometry has no piece {int(piece[i])} of object {objs[int(obj[i])]!r}")
        return ids

    def update(self, record: Any) -> ContactState:
        """Process one :class:`dlovr.sim.StepRecord` (or anything with ``step``, ``time``, ``points``,
        ``gripper_z`` and optionally ``contact_arrays``); return the step's contact state."""
        arrays = getattr(record, "contact_arrays", None)
        pts = np.asarray(record.points, dtype=float)
        pairs = None
        between = None
        point_of = np.zeros(0, dtype=np.int64)
        if arrays is not None and len(arrays.dist):
            point_of, seg_rows, seg_pos = _locate(arrays, pts)
            ids = self._piece_ids(arrays)
            ok = point_of >= 0
            pairs = (point_of[ok], ids[ok])
            between = (seg_pos, point_of[seg_rows], ids[seg_rows])
        elif arrays is not None:
            pairs = (np.zeros(0, np.int64), np.zeros(0, np.int64))
        prev = self.current
        topo = self.classify(pts, record.gripper_z, pairs, between)
        if prev is not None and (
            prev.topological is topo  # the cached situation, vectors and all: discretize is pure
            or (prev.topological == topo and _vector_independent(topo))
        ):
            disc = prev.discrete
        else:
            disc = discretize(topo, self.geometry.fact_book(), self.params)
        forces = _forces(topo, arrays, point_of)
        state = ContactState(
            int(record.step), float(record.time), topo, disc, forces,
            _tuple(getattr(record, "gripper_pos", _ORIGIN)),
            _tuple(getattr(record, "gripper_quat", _IDENTITY)),
            _tuple(getattr(record, "gripper_force", _ORIGIN)),
        )  # fmt: skip
        if prev is None or prev.discrete != disc or prev.topological != topo:
            self.changes.append(state)
        self.current = state
        self._debouncer.push(state.t, disc)
        return state

    def transitions(self) -> list[tuple[Kept[DiscreteSituation], tuple[str, ...]]]:
        """The kept situations with the classes of the transition into each (``()`` for the first;
        a landing after a flight is classed with the flight, ``S,E``)."""
        kept = self.kept
        return list(zip(kept, kept_classes(kept), strict=True))


def _same(a: np.ndarray, b: np.ndarray | None) -> bool:
    """Whether two integer or boolean arrays are equal, shape, dtype and all (cheaper than
    ``np.array_equal`` for the small arrays here; a dtype mismatch reads as a difference, which
    only costs a recomputation)."""
    return b is not None and a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _fields(b: LabelBudgets) -> tuple[np.ndarray, ...]:
    return b.normal, b.along, b.across, b.any


def _own(b: LabelBudgets) -> LabelBudgets:
    """Budgets with arrays of their own (a partial relabel writes rows of them in place)."""
    return LabelBudgets(*(np.array(a, dtype=float) for a in _fields(b)))


def _member(a: np.ndarray, sorted_b: np.ndarray) -> np.ndarray:
    """``np.isin(a, sorted_b)`` for a sorted ``sorted_b`` (cheaper for the small arrays here)."""
    if len(sorted_b) == 0:
        return np.zeros(len(a), dtype=bool)
    i = np.minimum(np.searchsorted(sorted_b, a), len(sorted_b) - 1)
    return sorted_b[i] == a


def _unique_pairs(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique (a, b) pairs of non-negative ints (b < 2**20), sorted by a then b."""
    u = np.unique(a.astype(np.int64) << 20 | b.astype(np.int64))
    return u >> 20, u & _LOW


_LOW = (1 << 20) - 1


_ORIGIN = (0.0, 0.0, 0.0)
_IDENTITY = (1.0, 0.0, 0.0, 0.0)


def _tuple(v: Any) -> Any:
    """A vector as a tuple of Python floats."""
    if isinstance(v, np.ndarray) and v.dtype == np.float64:
        return tuple(v.tolist())
    return tuple(float(x) for x in v)


@dataclass(eq=False)
class _Labels:
    """One geometric labelling: the queried pairs (``pi``, ``pc``) and query points ``pts`` then; per
    hit its query point ``pt``, piece ``pid``, ``faces`` and whether it lies within the enter and the
    leave distance (``between``: some hit lies between the two). Filled in later: the queried points
    ``q`` with their squared slacks (``pts`` then holds, for each, where it was last labelled), and
    the kept hits last made from it with the owners and keep mask used."""

    pi: np.ndarray
    pc: np.ndarray
    pts: np.ndarray
    pt: np.ndarray
    pid: np.ndarray
    faces: list[tuple[str, ...]]
    enter: np.ndarray
    leave: np.ndarray
    between: bool
    q: np.ndarray | None = None
    slack2: np.ndarray | None = None
    budgets: LabelBudgets | None = None
    owner: np.ndarray | None = None
    keep: np.ndarray | None = None
    hits: list[_Hit] = field(default_factory=list)


@dataclass(frozen=True)
class _Hit:
    point: int
    faces: tuple[str, ...]


def _vector_independent(topo: Situation) -> bool:
    """Discrete states depend on DLO vectors only through point/line decisions of E contacts on
    edges: without such contacts the discrete situation of an unchanged topology can be reused."""
    return not any(c.dlo.kind == "E" and any(e.type == "E" for e in c.env) for c in topo.contacts)


def _locate(arrays: Any, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each raw contact is on the cable.

    Returns the cable point of every contact (its vertex, or the nearer end of its segment; -1 for
    none), the rows of segment contacts, and their centerline points (the contact projected onto the
    segment).
    """
    point = np.asarray(arrays.point, dtype=np.int64)
    seg = np.asarray(arrays.segment, dtype=np.int64)
    pos = np.asarray(arrays.pos, dtype=float)
    usual = point.max() < 0 and seg.min() >= 0  # every contact is a segment's
    if usual:
        rows, s = np.arange(len(seg)), seg
    else:
        rows = np.nonzero((point < 0) & (seg >= 0))[0]
        s, pos = seg[rows], pos[rows]
    a = pts[s]
    ab = pts[s + 1] - a
    t = np.einsum("ij,ij->i", pos - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
    t = np.minimum(np.maximum(t, 0.0), 1.0)  # on the segment
    nearer = np.where(t < 0.5, s, s + 1)
    if usual:
        out = nearer
    else:
        out = point.copy()
        out[rows] = nearer
    return out, rows, a + t[:, None] * ab


def _forces(topo: Situation, arrays: Any, point_of: np.ndarray) -> tuple[float, ...]:
    if arrays is None or len(point_of) == 0:
        return tuple(0.0 for _ in topo.contacts)
    force = np.asarray(arrays.force, dtype=float)
    out = []
    for c in topo.contacts:
        if c.is_free or c.dlo.span is None:
            out.append(0.0)
            continue
        a, b = c.dlo.span
        out.append(float(force[(point_of >= a) & (point_of <= b)].sum()))
    return tuple(out)
