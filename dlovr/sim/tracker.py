"""Per-step contact extraction: a simulation step -> topological and discrete contact situation.

No MuJoCo: it reads the cable points and, when given, the raw contact arrays of
:class:`dlovr.sim.ContactArrays` (to know which points to classify and to attach normal forces).
Contacts are labelled geometrically (NOTES.md): a point touches a piece when its centerline is within
``radius + enter_tol`` of it, and keeps touching until it is farther than ``radius + leave_tol``
(hysteresis). The per-step situations are debounced (MODEL.md §4.2) into the demonstration's kept
situations.

The per-step work up to the touching hits runs in compiled kernels (:mod:`dlovr.sim.kernels`), one
call on a step that keeps its labels; model objects (topology, discrete situations) are built only on
the steps where the hits or the tip's decision change.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dlovr.geometry import SceneGeometry, primitives_per_point
from dlovr.model.discrete import DiscreteSituation, ModelParams, discretize
from dlovr.model.topology import Situation, situation_from_points, tip_touches
from dlovr.model.transitions import DEFAULT_HOLD_S, Debouncer, Kept, classify_step, is_transient
from dlovr.sim import kernels


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

    ``hold`` (s) is the flicker hold time of MODEL.md §4.2. ``changes`` lists every step at which the
    raw situation changed (what a recording stores); ``kept`` the debounced situations.

    ``reuse``: a step that queries the same (point, piece) pairs as the step of the last labelling,
    with every queried point closer to where it was then than its slack
    (:meth:`dlovr.geometry.SceneGeometry.label_slack`), or within its budgets along and across its
    faces, keeps those labels instead of labelling again: the same result, cheaper; points that moved
    farther are labelled again alone. ``labellings`` counts the steps that labelled every queried
    point, ``partial_labellings`` those that labelled some.
    """

    geometry: SceneGeometry
    params: ModelParams = field(default_factory=ModelParams)
    hold: float = DEFAULT_HOLD_S
    enter_tol: float = 5e-4
    leave_tol: float = 1e-3
    changes: list[ContactState] = field(default_factory=list)
    reuse: bool = True

    def __post_init__(self) -> None:
        self._debouncer: Debouncer[DiscreteSituation] = Debouncer(self.hold, is_transient)
        packed = self.geometry.packed()
        self._gf, self._gi, self._width = packed.floats, packed.ints, packed.width
        self._n_pieces = len(self.geometry.pieces)
        self._piece_map: tuple[Any, np.ndarray] | None = None
        self._tip: tuple[Any, list[np.ndarray]] | None = None
        self._tols: tuple[float, float, np.ndarray] | None = None
        self._spans: tuple[Any, np.ndarray] | None = None
        self._n1 = self._cap_c = -1
        self._forget()
        self.labellings = 0
        self.partial_labellings = 0
        self.current: ContactState | None = None

    def _forget(self) -> None:
        """No labels, no touching pairs, no hits."""
        self._labels: tuple[np.ndarray, ...] | None = None
        self._state = np.zeros(2, np.int64)  # number of touching keys, number of kept hits
        self._touching = np.zeros(16, np.int64)  # (point << 20 | piece id) in contact, sorted
        self._emitted = np.zeros((16, 1 + self._width), np.int64)  # kept hits: cable point, face ids
        self._hits: list[_Hit] = []
        self._signature: tuple[Any, ...] | None = None
        self._situation: Situation | None = None

    def restart(self, record: Any) -> ContactState:
        """Forget all history (hysteresis, changes, debouncing) and start again from ``record``.

        A recording starts this way, and its replay too, so both see the same contact states.
        """
        self._debouncer = Debouncer(self.hold, is_transient)
        self._forget()
        self.changes = []
        self.current = None
        return self.update(record)

    @property
    def kept(self) -> list[Kept[DiscreteSituation]]:
        return self._debouncer.kept

    def classify(
        self, pts: np.ndarray, gripper_z: Sequence[float] | None, kept_hits: list[_Hit]
    ) -> Situation:
        """Topological situation of the cable polyline ``pts`` from its touching hits (see
        :meth:`_label_step`) and the end-vertex rule."""
        geom = self.geometry
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

    def _thresholds(self) -> np.ndarray:
        """The centerline distances (m) at which a pair enters contact and leaves it."""
        if self._tols is None or self._tols[:2] != (self.enter_tol, self.leave_tol):
            r = self.geometry.radius
            self._tols = (self.enter_tol, self.leave_tol, np.array([r + self.enter_tol, r + self.leave_tol]))
        return self._tols[2]

    def _label_step(self, pts: np.ndarray, table: np.ndarray | None, objs: Any) -> list[_Hit]:
        """The touching hits of this step (:func:`dlovr.sim.kernels.track_step`): the pairs the
        simulator reports in ``table`` (and those touching at the last step; every point against
        every piece without a table) keep their last labels while their points stay within their
        slack or budgets; the others are labelled again (all of them, or the moved points alone)."""
        has = table is not None
        table = _NO_TABLE if table is None else table
        n1, nc = len(pts), len(table)
        if nc > self._cap_c or n1 != self._n1 or len(self._touching) != self._cap_h:
            self._scratch(n1, nc)
        lab = self._labels
        out, k, nq, n_again, bad = kernels.track_step(
            pts, table, has, self._piece_table(objs) if has else _NO_MAP, self._n_pieces, self.reuse,
            lab is not None, *(lab or _NO_LABELS), self._state, self._touching, self._emitted, self._pairs,
            self._owner, self._qpts, self._point_of, self._again,
        )  # fmt: skip
        if out >= kernels.FULL:
            thr, r = self._thresholds(), self.geometry.radius
            args = (self._gf, self._gi, self._width, r, self.leave_tol, r / 5.0, thr, self._qpts[:nq],
                    self._pairs[:k])  # fmt: skip
            if out == kernels.FULL or lab is None:
                self.labellings += 1
                lab = kernels.relabel_full(*args)
            else:
                self.partial_labellings += 1
                lab = (*lab[:5], kernels.relabel_partial(*args, self._again[:n_again], *lab[1:]))
            self._labels = lab
            if len(lab[5]) > len(self._touching):
                self._grow_hits(len(lab[5]))
            changed = kernels.update_hits(lab[5], self._owner, self._state, self._touching, self._emitted)
        elif out == kernels.BAD_PIECE:
            obj, piece = int(table[bad, kernels.T_OBJ]), int(table[bad, kernels.T_PIECE])
            name = objs[obj] if 0 <= obj < len(objs) else obj
            raise KeyError(f"the geometry has no piece {piece} of object {name!r}")
        else:
            changed = out == kernels.CHANGED
        if changed:
            face = self.geometry.face_tuple
            em = self._emitted[: self._state[1]]
            self._hits = [_Hit(p, face(row)) for p, row in zip(em[:, 0].tolist(), em[:, 1:], strict=True)]
        return self._hits

    def _scratch(self, n1: int, nc: int) -> None:
        """Per-step buffers of :func:`dlovr.sim.kernels.track_step` for ``n1`` points and at least
        ``nc`` contacts."""
        self._n1, self._cap_c, self._cap_h = n1, max(nc, 2 * self._cap_c, 16), len(self._touching)
        cap_k = n1 * self._n_pieces + 2 * self._cap_c + self._cap_h
        self._pairs = np.zeros((cap_k, 2), np.int64)
        self._owner = np.zeros(n1 + self._cap_c, np.int64)
        self._qpts = np.zeros((n1 + self._cap_c, 3))
        self._point_of = np.zeros(self._cap_c, np.int64)
        self._again = np.zeros(n1 + self._cap_c, np.int64)

    def _grow_hits(self, n: int) -> None:
        """Room for ``n`` touching keys and kept hits (their contents kept)."""
        cap = max(n, 2 * len(self._touching))
        touching, emitted = np.zeros(cap, np.int64), np.zeros((cap, 1 + self._width), np.int64)
        touching[: len(self._touching)] = self._touching
        emitted[: len(self._emitted)] = self._emitted
        self._touching, self._emitted = touching, emitted

    def _piece_table(self, objs: Any) -> np.ndarray:
        """Piece ids (positions in ``geometry.pieces``) by (object index in ``objs``, piece index)."""
        if self._piece_map is None or self._piece_map[0] is not objs:
            pieces = self.geometry.pieces
            table = np.full((max(len(objs), 1), max((p.index for p in pieces), default=0) + 1), -1, np.int64)
            row = {o: i for i, o in enumerate(objs)}
            for k, p in enumerate(pieces):
                if p.obj in row:
                    table[row[p.obj], p.index] = k
            self._piece_map = (objs, table)
        return self._piece_map[1]

    def update(self, record: Any) -> ContactState:
        """Process one :class:`dlovr.sim.StepRecord` (or anything with ``step``, ``time``, ``points``,
        ``gripper_z`` and optionally ``contact_arrays``); return the step's contact state."""
        arrays = getattr(record, "contact_arrays", None)
        pts = record.points
        if type(pts) is not np.ndarray or pts.dtype != np.float64 or not pts.flags.c_contiguous:
            pts = np.ascontiguousarray(pts, dtype=float)
        table = None if arrays is None else getattr(arrays, "table", None)
        if arrays is not None and table is None:
            table = _table_of(arrays)
        hits = self._label_step(pts, table, None if arrays is None else arrays.names[0])
        prev = self.current
        topo = self.classify(pts, record.gripper_z, hits)
        if prev is not None and (
            prev.topological is topo  # the cached situation, vectors and all: discretize is pure
            or (prev.topological == topo and _vector_independent(topo))
        ):
            disc = prev.discrete
        else:
            disc = discretize(topo, self.geometry.fact_book(), self.params)
        state = ContactState(
            int(record.step), float(record.time), topo, disc, self._forces(topo, table),
            _tuple(getattr(record, "gripper_pos", _ORIGIN)),
            _tuple(getattr(record, "gripper_quat", _IDENTITY)),
            _tuple(getattr(record, "gripper_force", _ORIGIN)),
        )  # fmt: skip
        if prev is None or prev.discrete != disc or prev.topological != topo:
            self.changes.append(state)
        self.current = state
        self._debouncer.push(state.t, disc)
        return state

    def _forces(self, topo: Situation, table: np.ndarray | None) -> tuple[float, ...]:
        """Per contact of ``topo``, the summed normal force of the simulator's contacts on its span."""
        if table is None or len(table) == 0:
            return tuple(0.0 for _ in topo.contacts)
        if self._spans is None or self._spans[0] is not topo:
            spans = [(-1, -1) if c.is_free or c.dlo.span is None else c.dlo.span for c in topo.contacts]
            self._spans = (topo, np.array(spans, dtype=np.int64).reshape(-1, 2))
        out = np.empty(len(topo.contacts))
        kernels.span_forces(self._spans[1], self._point_of, table, out)
        return tuple(out.tolist())

    def transitions(self) -> list[tuple[Kept[DiscreteSituation], tuple[str, ...]]]:
        """The kept situations with the classes of the transition into each (``()`` for the first)."""
        kept = self.kept
        return [
            (k, classify_step(kept[i - 1].situation, k.situation) if i else ()) for i, k in enumerate(kept)
        ]


_ORIGIN = (0.0, 0.0, 0.0)
_IDENTITY = (1.0, 0.0, 0.0, 0.0)


def _tuple(v: Any) -> Any:
    """A vector as a tuple of Python floats."""
    if isinstance(v, np.ndarray) and v.dtype == np.float64:
        return tuple(v.tolist())
    return tuple(float(x) for x in v)


@dataclass(frozen=True)
class _Hit:
    point: int
    faces: tuple[str, ...]


def _vector_independent(topo: Situation) -> bool:
    """Discrete states depend on DLO vectors only through point/line decisions of E contacts on
    edges: without such contacts the discrete situation of an unchanged topology can be reused."""
    return not any(c.dlo.kind == "E" and any(e.type == "E" for e in c.env) for c in topo.contacts)


def _table_of(arrays: Any) -> np.ndarray:
    """Contact rows (:mod:`dlovr.sim.kernels`) of raw contact arrays given as columns (``point``,
    ``segment``, ``obj``, ``piece``, ``pos``, ``force``: what the tracker reads)."""
    n = len(arrays.point)
    table = np.zeros((n, kernels.T_WIDTH))
    for col, name in ((kernels.T_POINT, "point"), (kernels.T_SEGMENT, "segment"), (kernels.T_OBJ, "obj"),
                      (kernels.T_PIECE, "piece"), (kernels.T_FORCE, "force")):  # fmt: skip
        table[:, col] = np.asarray(getattr(arrays, name), dtype=float).reshape(n)
    table[:, kernels.T_POS : kernels.T_POS + 3] = np.asarray(arrays.pos, dtype=float).reshape(n, 3)
    return table


_NO_TABLE = np.zeros((0, kernels.T_WIDTH))
_NO_MAP = np.full((1, 1), -1, np.int64)
_NO_LABELS = (
    np.zeros((0, 2), np.int64), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 6)),
    np.zeros((0, 4), np.int64),
)  # fmt: skip
