"""Per-step contact extraction: a simulation step -> topological and discrete contact situation.

No MuJoCo: it reads the cable points and, when given, the raw contact arrays of
:class:`dlovr.sim.ContactArrays` (to know which points to classify and to attach normal forces).
Contacts are labelled geometrically (docs/model.md): a point touches a piece when its centerline is within
``radius + enter_tol`` of it, and keeps touching until it is farther than ``radius + leave_tol``
(hysteresis). The per-step situations are debounced (docs/model.md: flicker, brief intermediate
states, flights) into the demonstration's kept situations.

The per-step work up to the touching hits runs in compiled kernels (:mod:`dlovr.sim.kernels`), one
call on a step that keeps its labels; model objects (topology, discrete situations) are built only on
the steps where the hits or the tip's decision change.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar, cast

import numpy as np

from dlovr.geometry import SceneGeometry, point_primitives
from dlovr.model.discrete import DiscreteSituation, Discretizer, ModelParams
from dlovr.model.topology import (
    Contact,
    DloPrimitive,
    EnvPrimitive,
    Situation,
    Vec3,
    situation_from_points,
    tip_touches,
)
from dlovr.model.transitions import (
    DEFAULT_FLIGHT_S,
    DEFAULT_HOLD_S,
    Debouncer,
    Kept,
    is_transient,
    kept_classes,
)
from dlovr.sim import track_kernels as tk
from dlovr.sim.kernels import T_FORCE, T_OBJ, T_PIECE, T_POINT, T_POS, T_SEGMENT, T_WIDTH
from dlovr.transforms import rotate_floats


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

    @classmethod
    def _of(
        cls, step: int, t: float, topological: Situation, discrete: DiscreteSituation,
        forces: tuple[float, ...], gripper_pos: tuple[float, float, float],
        gripper_quat: tuple[float, float, float, float], gripper_force: tuple[float, float, float],
    ) -> ContactState:
        """The state of these fields, as the constructor makes it but without the dataclass's
        ``__init__``, which sets a frozen field at a time (the tracker makes one every step)."""
        state = object.__new__(cls)
        state.__dict__.update(
            step=step, t=t, topological=topological, discrete=discrete, forces=forces,
            gripper_pos=gripper_pos, gripper_quat=gripper_quat, gripper_force=gripper_force,
        )
        return state

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

    ``tip_band_deg`` is the hysteresis of the end-vertex rule (docs/model.md, section 2): a tip that
    touches keeps touching until its last segment points into the surface by less than the tip angle
    minus this band (degrees); one that does not must pass the tip angle itself. ``line_band_deg`` is
    the hysteresis of the point-or-line decision on an edge (docs/model.md, section 3.2): an edge
    contact that is a line contact stays one until its DLO vector is more than the parallel tolerance
    plus this band (degrees) from the edge (:class:`dlovr.model.discrete.Discretizer`).

    ``hold`` (s) is the flicker hold time and ``flight`` (s) the flight time of the debouncing
    (docs/model.md, :class:`dlovr.model.transitions.Debouncer`). ``changes`` lists every step at
    which the raw situation changed (what a recording stores); ``kept`` the debounced situations.

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
    flight: float = DEFAULT_FLIGHT_S
    enter_tol: float = 5e-4
    leave_tol: float = 1e-3
    tip_band_deg: float = 3.0
    line_band_deg: float = 3.0
    changes: list[ContactState] = field(default_factory=list)
    reuse: bool = True

    def __post_init__(self) -> None:
        self._debouncer: Debouncer[DiscreteSituation] = Debouncer(self.hold, is_transient, self.flight)
        packed = self.geometry.packed()
        self._gf, self._gi, self._width = packed.floats, packed.ints, packed.width
        self._n_pieces = len(self.geometry.pieces)
        self._piece_map: tuple[Any, np.ndarray] | None = None
        self._tols: tuple[float, float, np.ndarray] | None = None
        self._made: dict[tuple[str, ...], Any] = {}  # environment primitives by face names
        self._disc: Discretizer | None = None
        self._normals: dict[str, list[float]] = {}
        # a point's faces and primitives by its face rows
        self._by_rows: dict[bytes, tuple[list[tuple[str, ...]], list[Any], int]] = {}
        # a number per distinct list of primitives (0: none), and the situations made from them
        self._codes: dict[tuple[Any, ...], int] = {(): 0}
        self._structures: dict[tuple[Any, ...], tuple[Situation, _Plan]] = {}
        self._g_envs: dict[int, tuple[Any, Vec3, tuple[EnvPrimitive, ...]]] = {}  # see _refreshed
        # the situation's plan (_refreshed) and its edge contacts (_edges_of)
        self._plan: _Plan = ([], ([], _NO_PAIRS), [], [None, None, None])
        self._env_version = 0  # changes when a point's primitives change (not on every new labelling)
        self._forget()
        self.labellings = 0
        self.partial_labellings = 0
        self.current: ContactState | None = None

    def _forget(self) -> None:
        """No labels, no touching pairs, no hits."""
        self._n1 = -1  # the work and label arrays are made afresh at the next step
        self._spans: tuple[Any, np.ndarray] = (None, _NO_SPANS)
        self._tip: tuple[int, list[list[float]]] | None = None
        self._signature: tuple[Any, ...] | None = None
        self._situation: Situation | None = None
        self._from: Situation | None = None  # the one _situation was refreshed from (None: made; _equal)
        self._tip_held = False  # the tip's own contact at the last step (the rule's hysteresis)
        if self._disc is not None:
            self._disc.forget()  # and the point-or-line decisions of the last step
        self._situation_env = -1  # the primitives' version the situation was made from
        # the plan and discretizer that made the current discrete situation (None: not so; _discretized)
        self._disc_plan: tuple[_Plan, Discretizer] | None = None
        self._z: Vec3 | None = None  # the gripper's z of the last situation made or refreshed
        # the situation's edge contacts' points (_edges_of) and the cable's points when it was made: it is
        # made again once one's DLO vector turns (_edge_turned, the kernel's check at this step)
        self._edge_pairs, self._edge_ref = _NO_PAIRS, _NO_REF
        self._edge_turned = False

    def restart(self, record: Any) -> ContactState:
        """Forget all history (hysteresis, changes, debouncing) and start again from ``record``.

        A recording starts this way, and its replay too, so both see the same contact states.
        """
        self._debouncer = Debouncer(self.hold, is_transient, self.flight)
        self._forget()
        self.changes = []
        self.current = None
        return self.update(record)

    @property
    def kept(self) -> list[Kept[DiscreteSituation]]:
        return self._debouncer.kept

    def classify(self, pts: np.ndarray, record: Any, quat: Sequence[float] | None = None) -> Situation:
        """Topological situation of the cable polyline ``pts`` from this step's touching hits (see
        :meth:`_label_step`) and the end-vertex rule; ``record.gripper_z`` (read only when the
        situation is made again) is the gripper's z axis, or ``quat``'s (floats, wxyz) when given.

        The situation is made again whenever the kept hits or the tip's decision change (which also
        refreshes its DLO vectors and the gripper's z), and whenever the DLO vector of one of its E
        contacts on an edge has turned by more than ``TURN_DEG`` (the point-or-line decision follows
        it). When no point's primitives
        changed, it is the last one with those annotations refreshed (:func:`_refreshed`): what
        ``situation_from_points`` makes of the same primitives, without contracting them again; so is
        one made from the same primitives and tip decision at an earlier step (:func:`_structure`)."""
        n = len(pts) - 1
        # the labels decide the situation, and the end-vertex rule when the tip has a contact:
        # cache the situation by both
        tip_info = self._tip
        if tip_info is None or tip_info[0] != self._env_version:  # the tip's faces, per primitives
            tip_faces = sorted({f for faces in self._point_faces[n] for f in faces})
            tip_info = self._tip = (self._env_version, [self._normal(f) for f in tip_faces])
        tip = None
        angle = self.params.tip_angle_deg
        if self._tip_held:  # a touching tip holds until the angle passes the threshold by the band
            angle = max(angle - self.tip_band_deg, 0.0)
        if tip_info[1]:
            a, b = pts[n - 1 :].tolist()  # the last DLO vector, rounded as pts[n] - pts[n - 1]
            tip = tip_touches([b[0] - a[0], b[1] - a[1], b[2] - a[2]], tip_info[1], angle)
        self._tip_held = bool(tip)
        signature = (n, self._version, tip)
        last = self._signature
        if signature == last and self._situation is not None and not self._edge_turned:
            return self._situation
        z = self._z = _gripper_z(record, self._z, quat)
        if (
            self._situation is not None and last is not None and last[0] == n and last[2] == tip
            and self._situation_env == self._env_version
        ):
            self._from = old = self._situation
            sit = _refreshed(old, pts, z, self._plan[0], self._g_envs)
            if self._spans[0] is old:  # the same spans: the kernel's sums hold for it
                self._spans = (sit, self._spans[1])
        else:  # made again, or made from the same primitives before (_structure)
            key = (len(pts), tip, *self._env_codes)
            made = self._structures, key, self._env, pts, self._normal, angle, z, self._g_envs
            (sit, self._plan), self._from = _structure(*made), None
        self._signature, self._situation, self._situation_env = signature, sit, self._env_version
        ks, pairs = self._plan[1]  # the vectors are those of these points (the kernel's check)
        self._edge_pairs, self._edge_ref = (pairs, pts.copy()) if ks else (_NO_PAIRS, _NO_REF)
        return sit

    def _normal(self, face: str) -> list[float]:
        """A face's outward unit normal (world frame) as Python floats, kept per face."""
        got = self._normals.get(face)
        if got is None:
            got = self._normals[face] = np.asarray(self.geometry.face_normal(face), dtype=float).tolist()
        return got

    def _params(self) -> np.ndarray:
        """The labelling's parameters for :func:`dlovr.sim.track_kernels.track_step`: the radius (m),
        the labels' contact tolerance (the leave one), the tangential tolerance, the centerline
        distances at which a pair enters contact and leaves it, and ``cos²(TURN_DEG)``."""
        tols = self._tols
        if tols is None or tols[0] != self.enter_tol or tols[1] != self.leave_tol:
            r = self.geometry.radius
            params = np.array([r, self.leave_tol, r / 5, r + self.enter_tol, r + self.leave_tol, _COS2])
            tols = self._tols = (self.enter_tol, self.leave_tol, params)
        return tols[2]

    def _label_step(self, pts: np.ndarray, table: np.ndarray | None, arrays: Any) -> None:
        """This step's touching hits (:func:`dlovr.sim.track_kernels.track_step`), and the forces on
        the last situation's contact spans: the pairs the simulator reports in ``table`` (and those
        touching at the last step; every point against every piece without a table) keep their last
        labels while their points stay within their slack or budgets; the others are labelled again
        (all of them, or the moved points alone). The environment primitives of the points whose hits
        changed are made again (``_env``, ``_point_faces``, ``_version``; ``_env_version`` when a
        point's primitives differ), kept by the point's face rows (the lists are shared, never changed)."""
        has = table is not None
        table = _NO_TABLE if table is None else table
        n1, nc = len(pts), len(table)
        if n1 != self._n1:
            self._alloc(n1, nc, 0)
        elif nc > self._cap_c:
            self._alloc(n1, max(nc, 2 * self._cap_c), self._cap_h)
        pm = self._piece_map
        if has and (pm is None or pm[0] is not arrays.names[0]):
            pm = self._piece_map = (arrays.names[0], _piece_table(self.geometry.pieces, arrays.names[0]))
        pmap = pm[1] if has and pm is not None else _NO_MAP
        skip = nc == 0 and self._quiet and has and self.reuse and not len(self._edge_pairs)  # track_step's
        out, changed, bad, self._edge_turned = _KEPT, False, -1, False  # what it would return then
        while not skip:
            out, changed, bad, self._edge_turned, self._quiet = _track_step(
                pts, table, has, pmap, self._spans[1], self._edge_pairs, self._edge_ref, self.reuse,
                self._gf, self._gi, self._params(), self._lab_i, self._lab_f, self._work_i, self._work_f,
            )
            if out != _GROW:
                break
            self._grow()
        if out != _KEPT:
            if out == tk.BAD_PIECE:
                obj, piece, objs = int(table[bad, T_OBJ]), int(table[bad, T_PIECE]), arrays.names[0]
                name = objs[obj] if 0 <= obj < len(objs) else obj
                raise KeyError(f"the geometry has no piece {piece} of object {name!r}")
            if out == tk.FULL:
                self.labellings += 1
            elif out == tk.PARTIAL:
                self.partial_labellings += 1
        if changed:
            group, start, env, by_rows = self._views.group, self._views.start, self._env, self._by_rows
            codes = self._env_codes
            for p in self._views.changed[: self._work_i[tk.W_CHANGED_N]].tolist():
                rows = group[start[p] : start[p + 1]]
                key = rows.tobytes()  # the point's face rows (their width is fixed)
                got = by_rows.get(key)
                if got is None:
                    faces = [self.geometry.face_tuple(row) for row in rows]
                    prims = point_primitives(faces, self._made)
                    code = self._codes.setdefault(tuple(prims), len(self._codes))
                    got = by_rows[key] = (faces, prims, code)
                self._point_faces[p] = got[0]
                if env[p] is not got[1] and env[p] != got[1]:
                    self._env_version += 1
                env[p] = got[1]
                codes[p] = got[2]
            self._version += 1

    def _grow(self) -> None:
        """Room for what :func:`dlovr.sim.track_kernels.track_step` asked (``GROW``)."""
        wi = self._work_i
        need_i, need_f, need_h = int(wi[tk.W_NEED_I]), int(wi[tk.W_NEED_F]), int(wi[tk.W_NEED_H])
        for name, need in (("_lab_i", need_i), ("_lab_f", need_f)):
            old = getattr(self, name)
            if need > len(old):
                new = np.zeros(max(need, 2 * len(old)), old.dtype)
                new[: len(old)] = old
                setattr(self, name, new)
        if need_h > self._cap_h:
            self._alloc(self._n1, self._cap_c, max(need_h, 2 * self._cap_h))

    def _alloc(self, n1: int, nc: int, cap_h: int) -> None:
        """Work arrays of :mod:`dlovr.sim.track_kernels` for ``n1`` points, at least ``nc`` contacts and
        ``cap_h`` kept hits; what a step keeps (the touching keys, the grouped hits) is copied over when
        the points stay the same, else the labels and hits start afresh."""
        old = self._work_i if n1 == self._n1 else None
        cap_c, cap_h = max(nc, 16), max(cap_h, 16)
        self._work_i, self._work_f = tk.new_work(n1, self._width, self._n_pieces, cap_c, cap_h, old)
        if old is None:
            self._lab_i, self._lab_f, self._quiet = *tk.no_labels(), False
            self._env: list[list[Any]] = [[] for _ in range(n1)]
            self._point_faces: list[list[tuple[str, ...]]] = [[] for _ in range(n1)]
            self._env_codes = [0] * n1  # the numbers (_codes) of the points' primitives
            self._version = 0
            self._env_version += 1
        self._n1, self._cap_c, self._cap_h = n1, cap_c, cap_h
        self._views = tk.work_views(self._work_i, self._work_f)

    def update(self, record: Any) -> ContactState:
        """Process one :class:`dlovr.sim.StepRecord` (or anything with ``step``, ``time``, ``points``,
        ``gripper_z`` and optionally ``contact_arrays``); return the step's contact state."""
        arrays = getattr(record, "contact_arrays", None)
        pts = record.points
        if type(pts) is not np.ndarray or pts.dtype is not _F64 or not pts.flags.c_contiguous:
            pts = np.ascontiguousarray(pts, dtype=float)
        table = None if arrays is None else getattr(arrays, "table", None)
        if arrays is not None and table is None:
            table = _table_of(arrays)
        poses = tuple(_tuple(getattr(record, k, v)) for k, v in _POSES)
        return self._state(record, int(record.step), float(record.time), pts, table, arrays, poses)

    def _state(
        self, record: Any, step: int, t: float, pts: np.ndarray, table: np.ndarray | None, arrays: Any,
        poses: tuple[Any, Any, Any], z_of_quat: bool = False,
    ) -> ContactState:
        """:meth:`update` of ``record`` given as its step, time, points (float64, C order), contact
        rows and arrays, and gripper position, quaternion and force as tuples of floats (what
        :class:`dlovr.sim.Simulator` has made of its record already); ``z_of_quat``: the record's
        ``gripper_z`` is the quaternion's z axis (a :class:`dlovr.sim.StepRecord`'s), taken from it."""
        self._label_step(pts, table, arrays)
        prev = self.current
        topo = self.classify(pts, record, poses[1] if z_of_quat else None)
        if prev is not None and prev.topological is topo:  # the cached situation: discretize is pure
            disc, same, new = prev.discrete, True, False
        elif prev is not None and not self._plan[1][0] and _equal(prev.topological, topo, self._from):
            disc, same, new = prev.discrete, True, False
            self._disc_plan = None  # its spans may differ from the plan's
        else:
            d, plan = self._discretizer(), self._plan
            disc, same, new = _discretized(d, prev, topo, plan, self._disc_plan)
            self._disc_plan = (plan, d)
        if table is not None and len(table) and self._spans[0] is topo:  # the kernel's sums
            forces = tuple(self._views.forces[: len(topo.contacts)].tolist())
        else:
            forces = self._forces(topo, table)
        gripper_pos, gripper_quat, gripper_force = poses
        state = ContactState._of(step, t, topo, disc, forces, gripper_pos, gripper_quat, gripper_force)
        if new:
            self.changes.append(state)
        self.current = state
        if same:  # the situation pushed at the last step again: the debouncer's push would compare it
            self._debouncer.extend(state.t)
        else:
            self._debouncer.push(state.t, disc)
        return state

    def _discretizer(self) -> Discretizer:
        """The scene's :class:`dlovr.model.discrete.Discretizer` for the current parameters."""
        d, book = self._disc, self.geometry.fact_book()
        band = self.line_band_deg
        if d is None or d.book is not book or d.params is not self.params or d.line_band_deg != band:
            d = self._disc = Discretizer(book, self.params, line_band_deg=band)
        return d

    def _forces(self, topo: Situation, table: np.ndarray | None) -> tuple[float, ...]:
        """Per contact of ``topo``, the summed normal force of the simulator's contacts on its span
        (summed by the kernels on the last situation's spans; again here when the situation changed)."""
        if table is None or len(table) == 0:
            return tuple(0.0 for _ in topo.contacts)
        if self._spans[0] is not topo:
            self._spans = spans = (topo, _spans_of(topo, self._plan[3]))
            views = self._views
            if len(spans[1]) > len(views.forces):
                raise RuntimeError("more contacts than the cable has points")
            tk.span_forces(spans[1], views.point_of, table, views.forces)
        return tuple(self._views.forces[: len(topo.contacts)].tolist())

    def transitions(self) -> list[tuple[Kept[DiscreteSituation], tuple[str, ...]]]:
        """The kept situations with the classes of the transition into each (``()`` for the first;
        a landing after a flight is classed with the flight, ``S,E``)."""
        kept = self.kept
        return list(zip(kept, kept_classes(kept), strict=True))


_ORIGIN = (0.0, 0.0, 0.0)
_Z = (0.0, 0.0, 1.0)
_T = TypeVar("_T")
_IDENTITY = (1.0, 0.0, 0.0, 0.0)
#: The gripper's pose and force that a state keeps: a record's attribute, and its default without one.
_POSES = (("gripper_pos", _ORIGIN), ("gripper_quat", _IDENTITY), ("gripper_force", _ORIGIN))


def _tuple(v: Any) -> Any:
    """A vector as a tuple of Python floats."""
    if type(v) is np.ndarray and v.dtype is _F64:
        return tuple(v.tolist())
    return tuple(float(x) for x in v)


def _piece_table(pieces: Sequence[Any], objs: Any) -> np.ndarray:
    """Piece ids (positions in ``pieces``, the geometry's) by (object index in ``objs``, piece index)."""
    table = np.full((max(len(objs), 1), max((p.index for p in pieces), default=0) + 1), -1, np.int64)
    row = {o: i for i, o in enumerate(objs)}
    for k, p in enumerate(pieces):
        if p.obj in row:
            table[row[p.obj], p.index] = k
    return table


def _structure(
    made: dict[tuple[Any, ...], tuple[Situation, _Plan]], key: tuple[Any, ...],
    env: list[list[EnvPrimitive]], pts: np.ndarray, normal: Any, angle: float, z: Vec3,
    g_envs: dict[int, tuple[Any, Vec3, tuple[EnvPrimitive, ...]]],
) -> tuple[Situation, _Plan]:
    """``situation_from_points`` of the points' primitives ``env``, the tip at ``angle`` (degrees)
    and the gripper's ``z``, and its :func:`_plan` with its :func:`_edges_of`. What it contracts
    depends on the primitives and the tip's decision alone (``key``: the cable's points, the tip's
    decision and a number per point's primitives), so a situation made (``made``) from the same ones
    before is refreshed instead (:func:`_refreshed`: the same object ``situation_from_points``
    makes, without contracting every point again): a cable crossing edges back and forth meets the
    same few again and again."""
    got = made.get(key)
    if got is not None:
        return _refreshed(got[0], pts, z, got[1][0], g_envs), got[1]
    sit = situation_from_points(env, pts[1:] - pts[:-1], normal, tip_angle_deg=angle, gripper_z=z)
    if len(made) >= _STRUCTURES_KEPT:
        made.clear()
    items = _plan(sit, len(pts) - 1)
    edges = _edges_of(sit, items)
    redo = sorted({*edges[0], *(k for k, it in enumerate(items) if it[6])})
    plan = (items, edges, redo, [None, None, None])
    made[key] = (sit, plan)
    return sit, plan


def _refreshed(
    sit: Situation, pts: np.ndarray, gripper_z: Vec3, plan: list[_PlanItem],
    g_envs: dict[int, tuple[Any, Vec3, tuple[EnvPrimitive, ...]]] | None = None,
) -> Situation:
    """``sit`` with the annotations that :func:`dlovr.model.topology.situation_from_points` takes
    from the cable and the gripper refreshed: each DLO primitive's vector ``D_i = P_{i+1} - P_i`` at
    its index (the last segment's at the tip) and the gripper primitive's ``z``. The same objects
    ``situation_from_points`` makes from unchanged primitives and tip decision, at a fraction of the
    cost (no contraction of every point's primitives). ``plan``: :func:`_plan` of ``sit`` (the
    tracker keeps it with the situation). ``g_envs`` (the tracker's, else none): by a plan's
    environment with the gripper (its identity), that environment, the ``z`` and the one made of them
    last: made again only when the ``z`` tuple is another (the tracker keeps one tuple while the
    gripper's z keeps its bits, :func:`_gripper_z`), so that the discretizer finds it by identity
    (:class:`dlovr.model.discrete.Discretizer`)."""
    xyz = pts.tolist()  # once: a contact's two points as Python floats
    if g_envs is None:
        g_envs = {}
    new = object.__new__
    contacts = []
    for kind, i, span, env, ia, ib, g in plan:
        a, b = xyz[ia], xyz[ib]
        dlo = new(DloPrimitive)  # the fields of a checked one: no __init__ (see _made), set one by one
        f = dlo.__dict__  # (cheaper than update's keywords)
        f["kind"], f["index"], f["span"] = kind, i, span
        f["vector"] = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
        if g:  # G's z is not compared: the canonical order stays
            got = g_envs.get(id(env))
            if got is None or got[0] is not env or got[1] is not gripper_z:
                if len(g_envs) >= _STRUCTURES_KEPT:
                    g_envs.clear()
                made = tuple(EnvPrimitive("G", (), gripper_z) if e.kind == "G" else e for e in env)
                got = g_envs[id(env)] = (env, gripper_z, made)
            env = got[2]
        c = new(Contact)
        f = c.__dict__
        f["dlo"], f["env"] = dlo, env
        contacts.append(c)
    return _made(Situation, contacts=tuple(contacts))


#: No E contacts on edges (:func:`_edges_of`'s point pairs), and no cable points kept for them.
_NO_PAIRS, _NO_REF = np.zeros((0, 2), np.int64), np.zeros((0, 3))

#: Per contact of a situation, what :func:`_refreshed` keeps of it: the DLO primitive's kind, index and
#: span, the environment primitives, the two points whose difference is its vector, and whether the
#: environment holds the gripper (whose ``z`` is refreshed).
_PlanItem = tuple[str, int, "tuple[int, int] | None", tuple[EnvPrimitive, ...], int, int, bool]


#: A situation's :func:`_plan`, its :func:`_edges_of`, the places of the contacts whose discrete
#: contact can follow its annotations (:meth:`dlovr.model.discrete.Discretizer.again`): the E contacts
#: on edges (their DLO vectors) and those with the gripper (its ``z``), and what is kept of the
#: situations made from it: the discretizer and the discrete situation it made last of one
#: (:func:`_discretized`), and the contacts' force spans (:func:`_spans_of`), all None until made.
_Plan = tuple[list[_PlanItem], tuple[list[int], np.ndarray], list[int], list[Any]]


def _plan(sit: Situation, n: int) -> list[_PlanItem]:
    """:func:`_refreshed`'s plan of ``sit``, a situation of a cable of ``n`` segments."""
    out: list[_PlanItem] = []
    for c in sit.contacts:
        d = c.dlo
        i = cast(int, d.index)
        ia, ib = (i - 1, i) if i == n else (i, i + 1)
        out.append((d.kind, i, d.span, c.env, ia, ib, any(e.kind == "G" for e in c.env)))
    return out


def _made(cls: type[_T], **fields: Any) -> _T:
    """A frozen dataclass of these fields without its ``__init__`` and checks (for objects whose
    fields come from a checked one: an env already canonical, the same contacts' structure)."""
    obj = object.__new__(cls)
    obj.__dict__.update(fields)
    return obj


def _edges_of(sit: Situation, plan: list[_PlanItem]) -> tuple[list[int], np.ndarray]:
    """The E contacts on edges (:func:`_on_edge`) of ``sit``: their places in it and, from its
    :func:`_plan`, the two points whose difference is each one's DLO vector (as
    :func:`dlovr.sim.track_kernels.turned` reads them: a (k, 2) array)."""
    ks = [k for k, c in enumerate(sit.contacts) if _on_edge(c)]
    return ks, np.array([(plan[k][4], plan[k][5]) for k in ks], np.int64).reshape(-1, 2)


def _discretized(
    d: Discretizer, prev: ContactState | None, topo: Situation, plan: _Plan,
    made: tuple[_Plan, Discretizer] | None,
) -> tuple[DiscreteSituation, bool, bool]:
    """The discrete situation of ``topo`` (made from ``plan``) by ``d``, whether it equals the last
    state's (``prev``) and whether the state is a change. When ``d`` made a discrete situation of
    this plan before (kept in the plan), only ``topo``'s contacts at the plan's redo places are made
    again from it (:meth:`dlovr.model.discrete.Discretizer.again`): a cable sliding over edges comes
    back to the same few plans, each step another of them. ``made``: the plan and discretizer that
    made ``prev``'s discrete situation (None: not so made; when they are these, the kept one is
    ``prev``'s and ``topo`` equals ``prev``'s situation but for the annotations)."""
    memo = plan[3]
    disc = d.again(memo[1], topo, plan[2]) if memo[0] is d else d(topo)
    memo[0], memo[1] = d, disc
    if prev is not None and made is not None and made[0] is plan and made[1] is d:
        same = disc is prev.discrete or prev.discrete == disc
        return disc, same, not same
    same = prev is not None and prev.discrete == disc
    return disc, same, not same or cast(ContactState, prev).topological != topo


def _gripper_z(record: Any, last: Vec3 | None, quat: Sequence[float] | None = None) -> Vec3:
    """``record.gripper_z`` as a tuple of Python floats (``(0, 0, 1)`` without one), or the z axis
    of ``quat`` (wxyz floats) when given (the same bits as a record's ``quat_rotate`` of its
    quaternion, without its arrays): ``last`` itself when it holds the same bits (so that the gripper
    primitives made of it are kept, see :func:`_refreshed`)."""
    if quat is not None:
        z = rotate_floats(quat, _Z)
    else:
        gripper_z = getattr(record, "gripper_z", None)
        z = cast(Vec3, tuple(float(x) for x in gripper_z)) if gripper_z is not None else (0.0, 0.0, 1.0)
    return last if last is not None and z == last and _same_bits(z, last) else z


def _same_bits(a: Any, b: Any) -> bool:
    """Do two equal tuples of floats hold the same bits (the signs of their zeros too)?"""
    sign = math.copysign
    return 0.0 not in a or all(x != 0.0 or sign(1.0, x) == sign(1.0, y) for x, y in zip(a, b, strict=True))


def _equal(last: Situation, topo: Situation, refreshed_from: Situation | None) -> bool:
    """``last == topo``, known without comparing when ``topo`` was refreshed from ``last``
    (:func:`_refreshed` keeps all that equality compares). The tracker asks it of a situation without
    E contacts on edges (its plan's :func:`_edges_of`): discrete states depend on DLO vectors only
    through their point-or-line decisions, so an equal one has the last discrete situation."""
    return refreshed_from is last or last == topo


def _on_edge(contact: Contact) -> bool:
    """Is ``contact`` an E contact on an edge (whose discrete state is a point-or-line decision)?"""
    if contact.dlo.kind != "E":
        return False
    for e in contact.env:
        if e.kind == "faces" and len(e.faces) == 2:  # an edge: EnvPrimitive.type "E"
            return True
    return False


def _spans_of(topo: Situation, memo: list[Any]) -> np.ndarray:
    """:func:`_force_spans` of ``topo`` as a (k, 2) array, kept in ``memo`` (its plan's: the spans
    follow from the contacts' structure alone, which the plan fixes)."""
    got = memo[2]
    if got is None:
        got = memo[2] = np.array(_force_spans(topo), dtype=np.int64).reshape(-1, 2)
    return got


def _force_spans(topo: Situation) -> list[tuple[int, int]]:
    """Per contact of ``topo``, the cable points whose simulator contacts its force sums (first, last;
    ``(-1, -1)``: none): its own span, but an end vertex that is free or only held hands its point to
    the interior contact next to it when that one touches the environment, where the end-vertex and
    gripped-end rules put what the end touched (docs/model.md, section 2)."""
    cs = topo.contacts
    spans = [(-1, -1) if c.is_free or c.dlo.span is None else c.dlo.span for c in cs]
    last = len(cs) - 1
    for end, inner in ((0, 1), (last, last - 1)):
        c, nxt = cs[end], cs[inner]
        if last < 2 or c.touches_environment or not nxt.touches_environment or c.dlo.span is None:
            continue
        p, (a, b) = c.dlo.span[0], spans[inner]
        if b == p - 1 or a == p + 1:  # the interior contact ends next to the end vertex
            spans[inner], spans[end] = (min(a, p), max(b, p)), (-1, -1)
    return spans


def _table_of(arrays: Any) -> np.ndarray:
    """Contact rows (:mod:`dlovr.sim.kernels`) of raw contact arrays given as columns (``point``,
    ``segment``, ``obj``, ``piece``, ``pos``, ``force``: what the tracker reads)."""
    n = len(arrays.point)
    table = np.zeros((n, T_WIDTH))
    for col, name in ((T_POINT, "point"), (T_SEGMENT, "segment"), (T_OBJ, "obj"), (T_PIECE, "piece"),
                      (T_FORCE, "force")):
        table[:, col] = np.asarray(getattr(arrays, name), dtype=float).reshape(n)
    table[:, T_POS : T_POS + 3] = np.asarray(arrays.pos, dtype=float).reshape(n, 3)
    return table


_F64 = np.dtype(np.float64)
_STRUCTURES_KEPT = 4096
"""How many situations :func:`_structure` keeps by their primitives (then none again)."""
#: An edge contact's DLO vector is looked at again (its point-or-line decision made again) once it has
#: turned by more than this since the last time (degrees): well inside the decision's 3° band.
TURN_DEG = 0.25
_COS2 = math.cos(math.radians(TURN_DEG)) ** 2
_KEPT, _GROW = tk.KEPT, tk.GROW
_track_step = tk.track_step
_NO_TABLE = np.zeros((0, T_WIDTH))
_NO_MAP = np.full((1, 1), -1, np.int64)
_NO_SPANS = np.zeros((0, 2), np.int64)
