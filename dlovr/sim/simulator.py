"""The simulator: steps the MuJoCo model, moves the gripper at bounded speed, checks for divergence
and records every step (cable points, raw contacts with normal forces, gripper wrench).

Typical use (headless)::

    from dlovr.scene import load_scene
    from dlovr.script import load_script
    from dlovr.sim import Simulator

    sim = Simulator(load_scene("table"), track=True)
    for step in sim.run(load_script("scenes/table.script.toml")):
        step.time, step.points, step.contacts, step.situation, step.discrete
    sim.tracker.transitions()   # the debounced situations with their transition classes
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import mujoco
import numpy as np

from dlovr.script import Script
from dlovr.sim import kernels
from dlovr.sim.build import _WARNINGS_FATAL, TIMESTEP, BuiltModel, Obstacle, SimulationDiverged, build_model
from dlovr.sim.contacts import ContactArrays, MjViews, RodContact
from dlovr.transforms import dot, norm, quat_normalize, quat_rotate

# --------------------------------------------------------------------------------------------------
# Per-step records


#: Default relative segment-length change beyond which a run is declared diverged (see Simulator).
DEFAULT_MAX_STRETCH = 0.25
@dataclass(frozen=True)
class StepRecord:
    """What one simulation step yields.

    ``points``: (n+1, 3) centerline points ``P_0..P_n``; ``vectors``: (n, 3) DLO vectors
    ``P_{i+1} - P_i``; gripper pose (``gripper_quat`` wxyz, ``gripper_z`` = ``G_z``) and the commanded
    target; ``contact_arrays``: raw rod-obstacle contacts as arrays (``contacts``: the same as
    :class:`RodContact` objects); ``self_contacts``: pairs of touching segments; ``gripper_force``:
    the force (N, world frame) the cable exerts on the gripper, as a wrist force sensor would read it;
    ``gripper_torque``: the moment of that load about the gripper's origin (N m, world frame), together
    the wrench a wrist force/torque sensor at the gripper would read.
    """

    step: int
    time: float
    points: np.ndarray
    gripper_pos: np.ndarray
    gripper_quat: np.ndarray
    target_pos: np.ndarray
    target_quat: np.ndarray
    contact_arrays: ContactArrays
    gripper_force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gripper_torque: np.ndarray = field(default_factory=lambda: np.zeros(3))
    state: Any = None  # the step's dlovr.sim.tracker.ContactState when the simulator tracks contacts

    @classmethod
    def _of(
        cls, step: int, time: float, points: np.ndarray, gripper_pos: np.ndarray, gripper_quat: np.ndarray,
        target_pos: np.ndarray, target_quat: np.ndarray, contact_arrays: ContactArrays,
        gripper_force: np.ndarray, gripper_torque: np.ndarray,
    ) -> StepRecord:
        """The record of these fields, as the constructor makes it but without the dataclass's
        ``__init__``, which sets a frozen field at a time (the simulator makes one every step)."""
        rec = object.__new__(cls)
        rec.__dict__.update(
            step=step, time=time, points=points, gripper_pos=gripper_pos, gripper_quat=gripper_quat,
            target_pos=target_pos, target_quat=target_quat, contact_arrays=contact_arrays,
            gripper_force=gripper_force, gripper_torque=gripper_torque, state=None,
        )
        return rec

    @cached_property
    def vectors(self) -> np.ndarray:
        """(n, 3) DLO vectors ``P_{i+1} - P_i`` (m, world frame)."""
        return np.diff(self.points, axis=0)

    @cached_property
    def gripper_z(self) -> np.ndarray:
        """The gripper's z axis ``G_z`` (unit, world frame)."""
        return quat_rotate(self.gripper_quat, np.array([0.0, 0.0, 1.0]))

    @property
    def situation(self) -> Any:
        """Topological contact situation of this step (``Simulator(..., track=True)``)."""
        return None if self.state is None else self.state.topological

    @property
    def discrete(self) -> Any:
        """Discrete contact situation of this step (``Simulator(..., track=True)``)."""
        return None if self.state is None else self.state.discrete

    @cached_property
    def contacts(self) -> tuple[RodContact, ...]:
        """The raw rod-obstacle contacts as :class:`RodContact` objects (built on first access)."""
        return self.contact_arrays.as_list()

    @property
    def self_contacts(self) -> tuple[tuple[int, int], ...]:
        """Pairs of touching segments of the rod (self-collision)."""
        return tuple((int(a), int(b)) for a, b in self.contact_arrays.self_pairs)


@dataclass(frozen=True)
class SimState:
    """Full checkpoint: MuJoCo's ``mjSTATE_INTEGRATION`` plus the simulator's own counters/target."""

    mj: np.ndarray
    step: int
    target_pos: np.ndarray
    target_quat: np.ndarray


# --------------------------------------------------------------------------------------------------
# Simulator

_NO_PAIRS = np.zeros((0, 2), np.int64)
_T_WIDTH = kernels.T_WIDTH
_NO_ROWS = np.zeros((0, _T_WIDTH))  # the contact rows of every step without any (nothing to write)
_O_WIDTH, _O_TORQUE, _O_POS, _O_QUAT = kernels.O_WIDTH, kernels.O_TORQUE, kernels.O_POS, kernels.O_QUAT
_step_record = kernels.step_record
_move_gripper = kernels.move_gripper


def _frozen(a: np.ndarray) -> np.ndarray:
    """``a`` (a private array) made read-only."""
    a.flags.writeable = False
    return a


def _pose_key(pos: Any, quat: Any) -> bytes | None:
    """A commanded pose's float64 values as bytes (exact: signed zeros and NaNs told apart; a ``None``
    quaternion gives fewer bytes), or None when either is not a float64 array of 3 and 4 values."""
    if type(pos) is not np.ndarray or pos.dtype != np.float64 or pos.shape != (3,):
        return None
    if quat is None:
        return pos.tobytes()
    if type(quat) is not np.ndarray or quat.dtype != np.float64 or quat.shape != (4,):
        return None
    return pos.tobytes() + quat.tobytes()


def _check_start(contacts: Sequence[RodContact], radius: float) -> None:
    """Raise ValueError when the cable's start pose penetrates an obstacle by more than half its
    ``radius`` (m)."""
    deep = [c for c in contacts if c.dist < -0.5 * radius]
    if deep:
        c = min(deep, key=lambda c: c.dist)
        raise ValueError(
            f"the cable's start pose (straight along -G_z from the gripper) penetrates {c.geom} "
            f"by {-c.dist * 1000:.1f} mm at segment {c.segment}: change the gripper pose"
        )


def obstacles_from_scene(scene: Any, pieces: dict[str, tuple[list[np.ndarray], bool]]) -> list[Obstacle]:
    """Obstacles of a ``dlovr.scene.Scene`` from its convex decomposition
    (``dlovr.geometry.scene_pieces``): MuJoCo piece ``k`` (geom ``"<obj>.P<k>"``) is geometry's
    ``Piece.index == k``."""
    out = []
    for obj in scene.objects:
        rgba = (*obj.color, 1.0) if getattr(obj, "color", None) else (0.6, 0.6, 0.65, 1.0)
        out.append(
            Obstacle(
                name=obj.name,
                pieces=[np.asarray(p, dtype=float) for p in pieces[obj.name][0]],
                pos=tuple(obj.pos),
                quat=tuple(obj.quat),
                rgba=rgba,
            )
        )
    return out


class Simulator:
    """Steps the cable model; the gripper follows a commanded target with bounded speed.

    ``Simulator(scene)`` with a ``dlovr.scene.Scene``, or ``Simulator.from_parts(obstacles, dlo,
    gripper)``. Set the target with :meth:`set_target`; :meth:`step` advances one time step (2 ms) and
    returns a :class:`StepRecord`; :meth:`run` plays a :class:`dlovr.script.Script`.

    ``max_speed`` (m/s) and ``max_angular_speed`` (rad/s) bound the gripper's motion toward the target;
    ``max_stretch`` is the relative change of a segment's length (stretch or squeeze) beyond which the
    run is declared diverged. Its default, 25%, lies above what ordinary motion does to the rod: its
    edges are soft constraints, and a tip pushed onto a surface at the gripper's top speed squeezes
    the segments behind it by up to about 11% for a few steps (measured on the table scene at 40
    segments; 80-segment demos reach about 18%), while a numerical blow-up goes far beyond.
    ``pieces`` fixes the obstacles' convex decomposition (``dlovr.geometry.scene_pieces``; computed
    when not given; kept as ``sim.pieces``). ``track=True`` (scene needed) also extracts the contact
    states every step: ``sim.tracker`` is a :class:`dlovr.sim.tracker.ContactTracker` and each record
    carries its ``state`` (``.situation``, ``.discrete``); ``geometry``: the scene's
    :class:`dlovr.geometry.SceneGeometry` for the tracker, when made before (it is only read, so two
    simulators of one scene, e.g. a trial's program run and its open-loop replay, may share it).
    """

    def __init__(
        self,
        scene: Any = None,
        *,
        built: BuiltModel | None = None,
        max_speed: float = 0.25,
        max_angular_speed: float = 2.0,
        max_stretch: float = DEFAULT_MAX_STRETCH,
        track: bool = False,
        pieces: dict[str, tuple[list[np.ndarray], bool]] | None = None,
        geometry: Any = None,
    ):
        self.pieces = pieces
        if built is None:
            if scene is None:
                raise ValueError("Simulator needs a scene or a built model")
            if self.pieces is None:
                from dlovr.geometry import scene_pieces

                self.pieces = scene_pieces(scene)
            built = build_model(obstacles_from_scene(scene, self.pieces), scene.dlo, scene.gripper)
        self.scene = scene
        self.tracker: Any = None
        self.behind: Any = None  # a dlovr.sim.behind.TrackingThread: it tracks the steps instead
        if track:
            if scene is None:
                raise ValueError("contact tracking needs the scene")
            from dlovr.geometry import SceneGeometry
            from dlovr.sim.tracker import ContactTracker

            if geometry is None:
                geometry = SceneGeometry.from_scene(scene, pieces=self.pieces)
            self.tracker = ContactTracker(geometry, scene.params)
        self.built = built
        self.max_stretch = max_stretch
        self.model = built.model
        self.data = mujoco.MjData(self.model)
        self.max_speed = float(max_speed)
        self.max_angular_speed = float(max_angular_speed)
        self.step_index = 0
        m = self.model
        self._fatal = np.array([int(getattr(mujoco.mjtWarning, w)) for w in _WARNINGS_FATAL])
        d = self.data
        # views of MuJoCo's fixed arrays, taken once (each attribute access makes a new view)
        b = built
        self._xpos = d.flexvert_xpos[b.vert_adr : b.vert_adr + b.nvert]
        self._mocap_pos, self._mocap_quat = d.mocap_pos[b.mocap_id], d.mocap_quat[b.mocap_id]
        self._dt = float(m.opt.timestep)
        self._pts_shape = (b.nvert, 3)
        self._geom_names = {g: mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) for g in built.geom_piece}
        objs = tuple(dict.fromkeys(o for o, _ in built.geom_piece.values()))
        self._obj_of_geom = np.full(m.ngeom, -1, dtype=np.int64)
        self._piece_of_geom = np.full(m.ngeom, -1, dtype=np.int64)
        for g, (o, k) in built.geom_piece.items():
            self._obj_of_geom[g] = objs.index(o)
            self._piece_of_geom[g] = k
        self._names = (objs, self._geom_names)
        eq = mujoco.mjtObj.mjOBJ_EQUALITY
        self._hold_rows: tuple[int, np.ndarray] = (-1, np.zeros(0, np.int64))
        self._hold_ids = np.array([mujoco.mj_name2id(m, eq, f"hold_{i}") for i in range(2)], dtype=np.int32)
        mujoco.mj_forward(m, self.data)
        self._views = MjViews(  # after mj_forward: its efc_force allocated
            m, d, self._xpos, (self._mocap_pos, self._mocap_quat), b.flex_id, self._fatal,
            self._piece_of_geom, self._obj_of_geom,
        )
        self._reset_warnings()
        self.target_pos = _frozen(self._mocap_pos.copy())
        self.target_quat = _frozen(self._mocap_quat.copy())
        # set_target's last float64 input as bytes, and the targets it made (see set_target)
        self._last_command: tuple[bytes, np.ndarray, np.ndarray] | None = None
        _check_start(self.contacts(), float(m.flex_radius[built.flex_id]))

    @classmethod
    def from_parts(cls, obstacles: Sequence[Obstacle], dlo: Any, gripper: Any, **kw: Any) -> Simulator:
        """Simulator from obstacles given as convex pieces (no scene file needed)."""
        timestep = kw.pop("timestep", TIMESTEP)
        return cls(built=build_model(obstacles, dlo, gripper, timestep=timestep), **kw)

    # -- gripper ------------------------------------------------------------------------------------

    def set_target(
        self, pos: Sequence[float] | np.ndarray, quat: Sequence[float] | np.ndarray | None = None
    ) -> None:
        """Command the gripper pose (world ``pos``, ``quat`` wxyz; ``None`` keeps the orientation).

        Called every step by programs and scripts: the checks run on Python floats, and the
        quaternion is divided by its :func:`dlovr.transforms.norm` computed once (the same bits as
        ``quat_normalize``). The target arrays are private copies made read-only, so that the steps'
        records share them instead of copying them (a target assigned directly is copied by each
        record while it is writeable).

        A pose given as float64 arrays bit for bit equal to the last one (signed zeros and NaNs told
        apart), while the targets are still those it made, returns at once: it would make the same
        targets (a hold, a still stretch of a track)."""
        key = _pose_key(pos, quat)
        last = self._last_command
        if key is not None and last is not None and key == last[0] and self.target_pos is last[1] \
                and self.target_quat is last[2]:
            return
        p = np.array(pos, dtype=float)  # a private copy
        if p.shape != (3,) or not all(map(math.isfinite, p.tolist())):
            raise ValueError(f"gripper target position must be 3 finite numbers, got {pos!r}")
        self.target_pos = _frozen(p)
        if quat is not None:
            q = np.asarray(quat, dtype=float)
            w = q.tolist() if q.shape == (4,) else None
            n = math.sqrt(dot(w, w)) if w is not None and all(map(math.isfinite, w)) else 0.0
            if w is None or n < 1e-9:
                raise ValueError(f"gripper target quaternion must be 4 finite numbers, not all 0: {quat!r}")
            self.target_quat = _frozen(np.array([x / n for x in w]))  # q / n, element by element
        self._last_command = None if key is None else (key, self.target_pos, self.target_quat)

    def _move_mocap(self) -> None:
        """The gripper one step toward its target at bounded speed (:func:`dlovr.sim.kernels.move_gripper`,
        in MuJoCo's mocap arrays)."""
        dt = self._dt
        _move_gripper(
            self._mocap_pos, self._mocap_quat, self.target_pos, self.target_quat, self.max_speed * dt,
            self.max_angular_speed * dt,
        )

    # -- stepping -----------------------------------------------------------------------------------

    @property
    def max_stretch(self) -> float:
        """Relative segment stretch beyond which a step is declared diverged."""
        return self._max_stretch

    @max_stretch.setter
    def max_stretch(self, value: float) -> None:
        self._max_stretch = float(value)
        seg = float(self.built.seg_length)
        # squared segment lengths beyond these go to the exact test (bounds slightly inside it)
        self._bounds = np.array(
            [
                (seg * (1.0 - self._max_stretch)) ** 2 * (1.0 + 1e-9),
                (seg * (1.0 + self._max_stretch)) ** 2 * (1.0 - 1e-9),
                seg,
                self._max_stretch,
            ]
        )

    @property
    def time(self) -> float:
        return float(self.data.time)

    def points(self) -> np.ndarray:
        """Centerline points P_0..P_n, shape (n+1, 3) (a copy)."""
        return self._xpos.copy()

    def step(self, n: int = 1) -> StepRecord:
        """Advance ``n`` time steps; return the record of the last one. Raises SimulationDiverged."""
        m, d, tracker, dt, behind = self.model, self.data, self.tracker, self._dt, self.behind
        state = rec = None
        for _ in range(n):
            _move_gripper(  # self._move_mocap(), inline: this runs every step
                self._mocap_pos, self._mocap_quat, self.target_pos, self.target_quat, self.max_speed * dt,
                self.max_angular_speed * dt,
            )
            mujoco.mj_step(m, d)
            self.step_index += 1
            rec, poses = self._record(True)
            if behind is not None:  # tracked on its thread (dlovr.sim.behind.tracking_behind)
                behind.push(rec, poses)
            elif tracker is not None:  # tracker.update(rec) of what the record's kernel made already
                ca = rec.contact_arrays
                state = tracker._state(rec, rec.step, rec.time, rec.points, ca.table, ca, poses, True)
        if state is not None:
            object.__setattr__(rec, "state", state)
        assert rec is not None, "step(n) needs n >= 1"
        return rec

    def _diverged(self, code: int, index: int, value: float) -> SimulationDiverged:
        """The error of a failed divergence check (see :func:`dlovr.sim.kernels.step_record`)."""
        d = self.data
        if code == 1:
            now = d.warning.number
            w = next((w for w, n0 in zip(self._fatal, self._warnings_each, strict=True) if now[w] > n0), None)
            name = "count changed" if w is None else mujoco.mjtWarning(int(w)).name
            self._reset_warnings()
            return SimulationDiverged(self.step_index, d.time, f"MuJoCo warning {name}")
        if code == 2:
            return SimulationDiverged(self.step_index, d.time, "NaN/inf in the state")
        if code == 3:
            return SimulationDiverged(self.step_index, d.time, "NaN/inf in the cable points")
        why = f"segment {index} length off by {value:.1%} (bound {self.max_stretch:.0%})"
        return SimulationDiverged(self.step_index, d.time, why)

    def _reset_warnings(self) -> None:
        """Take MuJoCo's current warning counts as the baseline of the divergence checks."""
        self._warnings_each = self.data.warning.number[self._fatal].copy()
        self._views.set_warning_base(int(self._warnings_each.sum()))

    def contact_arrays(self) -> ContactArrays:
        """Raw rod contacts of the current step as arrays (no per-contact Python objects)."""
        return self.record().contact_arrays

    def contacts(self) -> tuple[RodContact, ...]:
        """Raw contacts of the rod with obstacle pieces at the current step, as objects."""
        return self.contact_arrays().as_list()

    def record(self, *, check: bool = False) -> StepRecord:
        """The current step's record; with ``check`` the divergence checks too (raises
        SimulationDiverged): the warnings counted since the last reset, NaN/inf in the state or the
        cable points, a segment stretched beyond ``max_stretch``. One kernel call
        (:func:`dlovr.sim.kernels.step_record`) reads MuJoCo's arrays once."""
        return self._record(check)[0]

    def _record(self, check: bool) -> tuple[StepRecord, tuple[Any, Any, Any]]:
        """:meth:`record`, and the gripper's position, quaternion and force as tuples of floats (what
        the tracker's state keeps). The record's gripper force, torque, position and quaternion are
        parts of one array (:data:`dlovr.sim.kernels.O_WIDTH`) that the kernel fills."""
        views = self._views
        ncon = self.data.ncon
        empty = np.empty
        pts, out = empty(self._pts_shape), empty(_O_WIDTH)
        table = empty((ncon, _T_WIDTH)) if ncon else _NO_ROWS
        if ncon and not views.layout_known:  # the contact structs' layout, taken at the first contact
            views.contacts()
        arena = views.arena
        args = views.mj, views.mem, arena, views.cfg, self._bounds, ncon, pts, table, out
        code, index, value, rows, nself, ne, time, poses = _step_record(*args)
        if ne != self._hold_rows[0]:  # the holding constraints' rows for this count, and again
            self._set_hold_rows(ne)
            code, index, value, rows, nself, ne, time, poses = _step_record(*args[:3], views.cfg, *args[4:])
        if check and code:
            raise self._diverged(code, index, value)
        pairs = _NO_PAIRS
        if nself:
            pairs = empty((nself, 2), np.int64)
            kernels.self_pairs(ncon, arena, views.cfg, pairs)
        tp, tq, names = self.target_pos, self.target_quat, self._names  # targets shared when read-only
        rec = StepRecord._of(
            self.step_index,
            time,
            pts,
            out[_O_POS:_O_QUAT],
            out[_O_QUAT:],
            tp.copy() if tp.flags.writeable else tp,
            tq.copy() if tq.flags.writeable else tq,
            ContactArrays._of(table if rows == ncon else table[:rows] if rows else _NO_ROWS, pairs, names),
            out[:_O_TORQUE],
            out[_O_TORQUE:_O_POS],
        )
        return rec, poses

    def _set_hold_rows(self, ne: int) -> None:
        """The holding constraints' rows among MuJoCo's ``ne`` equality constraint rows (which come
        first, in a fixed layout while ``ne`` is unchanged)."""
        ids = self.data.efc_id[:ne]
        rows = np.nonzero((ids == self._hold_ids[0]) | (ids == self._hold_ids[1]))[0]
        self._hold_rows = (ne, rows)
        self._views.set_hold_rows(rows)

    def gripper_force(self) -> np.ndarray:
        """Force (N, world frame) the cable exerts on the gripper: the two holding constraints' forces
        (a hanging cable pulls with its weight, -m g along z)."""
        return self.record().gripper_force

    def gripper_wrench(self) -> tuple[np.ndarray, np.ndarray]:
        """Force (N) and torque (N m, about the gripper's origin), world frame, that the cable exerts on
        the gripper through its two holding constraints (see :func:`dlovr.sim.kernels.hold_torque`)."""
        rec = self.record()
        return rec.gripper_force, rec.gripper_torque

    def run(self, script: Script, *, settle: float = 0.0) -> Iterator[StepRecord]:
        """Play ``script`` from the current gripper pose; yield one record per step. Its first waypoint
        is reached from the gripper's pose at the call over its ``duration``; ``settle`` s more at the
        last, then on until the gripper is there (:func:`steps_to_target`): a demonstration ends there."""
        mid, dt = self.built.mocap_id, self._dt
        plan = script.plan(self.data.mocap_pos[mid], self.data.mocap_quat[mid])
        nsteps = round((script.total_duration + settle) / dt)
        for k in range(1, nsteps + 1):
            pos, quat = plan.at(k * dt)
            self.set_target(pos, quat)
            yield self.step()
        for _ in range(steps_to_target(self)):
            yield self.step()

    # -- state --------------------------------------------------------------------------------------

    def get_state(self) -> SimState:
        """Checkpoint with ``mjSTATE_INTEGRATION`` (includes the rod's plastic state and warm start)."""
        m, d = self.model, self.data
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        buf = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, buf, spec)
        return SimState(buf, self.step_index, self.target_pos.copy(), self.target_quat.copy())

    def set_state(self, state: SimState) -> None:
        """Restore a checkpoint from :meth:`get_state`; later steps are bit-identical to the original."""
        m, d = self.model, self.data
        mujoco.mj_setState(m, d, state.mj, mujoco.mjtState.mjSTATE_INTEGRATION)
        mujoco.mj_forward(m, d)
        self._reset_warnings()
        self.step_index = state.step
        self.target_pos = _frozen(state.target_pos.copy())
        self.target_quat = _frozen(state.target_quat.copy())


def steps_to_target(sim: Simulator) -> int:
    """The steps ``sim``'s gripper takes to reach its target from where it is: 0 where it is there,
    exactly. It lags its target where that moves faster than ``max_speed`` (m/s) or
    ``max_angular_speed`` (rad/s), and :func:`dlovr.sim.kernels.move_gripper` puts it on the target
    once that lies within one step."""
    mid, dt = sim.built.mocap_id, float(sim.model.opt.timestep)
    pos, quat = sim.data.mocap_pos[mid], sim.data.mocap_quat[mid]
    if np.array_equal(pos, sim.target_pos) and np.array_equal(quat, sim.target_quat):
        return 0
    dist = norm(sim.target_pos - pos)  # how long a recording runs: the same on every machine (no BLAS)
    angle = 2.0 * math.acos(min(1.0, abs(dot(quat_normalize(quat), quat_normalize(sim.target_quat)))))
    return max(math.ceil(max(dist / (sim.max_speed * dt), angle / (sim.max_angular_speed * dt))), 1)
