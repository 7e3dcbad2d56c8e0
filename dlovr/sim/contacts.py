"""Raw contacts of the rod, read from MuJoCo's contact structs in place by the per-step kernel
(:func:`dlovr.sim.kernels.step_record`; no per-contact Python objects).

Frames and units: world frame, metres, newtons. A contact's ``normal`` points from the obstacle toward
the rod; its normal force is decoded as ``mj_contactForce`` does.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from functools import cached_property

import mujoco
import numpy as np

from dlovr.sim.kernels import (
    C_FLEX,
    C_HEAD,
    C_LAYOUT,
    C_MOCAP_POS,
    C_MOCAP_QUAT,
    C_NFATAL,
    C_NGEOM,
    C_NQ,
    C_NV,
    C_NVERT,
    C_PYRAMIDAL,
    C_QPOS,
    C_QVEL,
    C_S_ARENA,
    C_S_EFC,
    C_S_END,
    C_S_NCON,
    C_WARN_BASE,
    C_XPOS,
    T_ACTIVE,
    T_DIST,
    T_FORCE,
    T_GEOM,
    T_NORMAL,
    T_OBJ,
    T_PIECE,
    T_POINT,
    T_POS,
    T_SEGMENT,
    pack_config,
)


@dataclass(frozen=True)
class RodContact:
    """One raw MuJoCo contact between the rod and an obstacle piece.

    ``point``: cable point index when MuJoCo reports a vertex (plane-like contacts), else ``None``;
    ``segment``: segment index (segment ``i`` joins points ``i`` and ``i+1``) when it reports an element.
    ``normal`` points from the obstacle toward the rod; ``pos`` is MuJoCo's contact point (midway),
    ``surface`` the obstacle's surface point; ``dist`` < 0 is penetration. ``force``: normal force (N),
    0 for contacts in the detect-only gap band (``active`` False).
    """

    point: int | None
    segment: int | None
    obj: str
    piece: int
    geom: str
    dist: float
    normal: np.ndarray
    pos: np.ndarray
    surface: np.ndarray
    force: float
    active: bool


@dataclass(frozen=True, eq=False)
class ContactArrays:
    """Raw rod-obstacle contacts of one step, one row per MuJoCo contact (see :class:`RodContact`).

    ``table``: (n, 14) rows as the kernels write them (:mod:`dlovr.sim.kernels`): point, segment,
    geom, obj, piece (integers held exactly), dist, normal (3), pos (3), force, active (0/1). The
    columns are also given as typed arrays: ``point``/``segment`` (-1 where MuJoCo does not report a
    vertex/element), ``geom`` (MuJoCo geom id), ``obj`` (index into ``names[0]``, the object names),
    ``piece``, ``dist``, ``normal``, ``pos``, ``force``, ``active``; ``names[1]``: geom names by
    ``geom`` id. ``self_pairs``: (k, 2) touching segment pairs of the rod itself.
    """

    table: np.ndarray
    self_pairs: np.ndarray
    names: tuple[tuple[str, ...], dict[int, str]]

    @classmethod
    def _of(
        cls, table: np.ndarray, self_pairs: np.ndarray, names: tuple[tuple[str, ...], dict[int, str]]
    ) -> ContactArrays:
        """The arrays of these fields, as the constructor makes them but without the dataclass's
        ``__init__``, which sets a frozen field at a time (the simulator makes one every step)."""
        arrays = object.__new__(cls)
        arrays.__dict__.update(table=table, self_pairs=self_pairs, names=names)
        return arrays

    def __len__(self) -> int:
        return len(self.table)

    def _column(self, col: int) -> np.ndarray:
        return self.table[:, col].astype(np.int64)

    point = cached_property(lambda self: self._column(T_POINT))
    segment = cached_property(lambda self: self._column(T_SEGMENT))
    geom = cached_property(lambda self: self._column(T_GEOM))
    obj = cached_property(lambda self: self._column(T_OBJ))
    piece = cached_property(lambda self: self._column(T_PIECE))
    dist = cached_property(lambda self: self.table[:, T_DIST].copy())
    normal = cached_property(lambda self: self.table[:, T_NORMAL : T_NORMAL + 3].copy())
    pos = cached_property(lambda self: self.table[:, T_POS : T_POS + 3].copy())
    force = cached_property(lambda self: self.table[:, T_FORCE].copy())
    active = cached_property(lambda self: self.table[:, T_ACTIVE] != 0.0)

    @property
    def surface(self) -> np.ndarray:
        """Surface points of the obstacles (``pos - normal * dist / 2``)."""
        return self.pos - self.normal * (self.dist / 2.0)[:, None]

    def as_list(self) -> tuple[RodContact, ...]:
        objs, gnames = self.names
        surf = self.surface
        return tuple(
            RodContact(
                point=int(self.point[i]) if self.point[i] >= 0 else None,
                segment=int(self.segment[i]) if self.segment[i] >= 0 else None,
                obj=objs[self.obj[i]],
                piece=int(self.piece[i]),
                geom=gnames[int(self.geom[i])],
                dist=float(self.dist[i]),
                normal=self.normal[i].copy(),
                pos=self.pos[i].copy(),
                surface=surf[i].copy(),
                force=float(self.force[i]),
                active=bool(self.active[i]),
            )
            for i in range(len(self.table))
        )


_NO_PAIRS = np.zeros((0, 2), int)


class MjViews:
    """MuJoCo's arrays of one ``MjData`` as the per-step kernel reads them in place
    (:func:`dlovr.sim.kernels.step_record`), views taken once: each attribute access of the bindings
    makes a new view, and numba checks every argument of a call.

    ``mj``: one float64 view over qpos, qvel, the cable points and the gripper's mocap position and
    quaternion (they lie in ``data``'s buffer, fixed for its life); ``mem``: the ``mjData`` struct
    itself up to its ``efc_force`` pointer, as int64 (its warning structs, ``ncon``, ``ne``,
    ``nefc``, ``time``, and the pointers to the arena and to this step's ``efc_force``, which the
    constraint solver allocates in the arena anew each step); ``arena``: the arena (contacts first,
    ``d->contact = d->arena``, then the constraint arrays), fixed for the life of ``data``; ``cfg``:
    the kernel's configuration (``dlovr.sim.kernels.C_*``: the warning baseline, the rod's flex id,
    the cone, where the arrays lie in ``mj`` and the fields in ``mem``, the contact structs' layout
    from the bindings' own views (taken at the first contact: the bindings give an empty contact list
    no address), the fatal warnings, the obstacle piece and object of each geom, the holding
    constraints' rows). The struct's fields are found by their values (:func:`_struct_fields`), not
    from a header. Keep ``data`` alive as long as the views; call with ``data`` after ``mj_forward``
    (its ``efc_force`` allocated).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        xpos: np.ndarray,
        mocap: tuple[np.ndarray, np.ndarray],
        flex: int,
        fatal: np.ndarray,
        piece_of_geom: np.ndarray,
        obj_of_geom: np.ndarray,
    ):
        arrays = (data.qpos, data.qvel, xpos, *mocap)
        ptrs = [_address(a) for a in arrays]
        lo = min(ptrs)
        hi = max(p + a.nbytes for p, a in zip(ptrs, arrays, strict=True))
        if any((p - lo) % 8 for p in ptrs) or not all(a.flags.c_contiguous for a in arrays):
            raise RuntimeError("unexpected MuJoCo data layout")
        self.mj = np.ctypeslib.as_array((ctypes.c_double * ((hi - lo) // 8)).from_address(lo))
        fields = _struct_fields(data)
        base = data._address
        size = fields[C_S_EFC - C_S_NCON] + 1
        self.mem = np.ctypeslib.as_array((ctypes.c_int64 * size).from_address(base))
        arena = int(self.mem[fields[C_S_ARENA - C_S_NCON]])
        self.arena = np.ctypeslib.as_array((ctypes.c_double * (int(data.narena) // 8)).from_address(arena))
        number = data.warning.number  # every other int32 of the warning structs
        self._data = data
        self.layout_known = False  # the contact structs' layout taken (contacts())
        q, v, x, mp, mq = ((p - lo) // 8 for p in ptrs)
        self._head = np.zeros(C_HEAD, np.int64)
        self._head[[C_FLEX, C_PYRAMIDAL, C_NFATAL, C_NGEOM]] = (
            flex, int(model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL), len(fatal), len(piece_of_geom)
        )
        self._head[[C_XPOS, C_QPOS, C_NQ, C_QVEL, C_NV, C_NVERT, C_MOCAP_POS, C_MOCAP_QUAT]] = (
            x, q, len(data.qpos), v, len(data.qvel), len(xpos), mp, mq
        )
        self._head[C_S_NCON:C_S_END] = fields
        self._tail = (
            (_address(number) - base) // 4 + np.asarray(fatal, np.int64) * (number.strides[0] // 4),
            np.asarray(piece_of_geom, np.int64),
            np.asarray(obj_of_geom, np.int64),
        )
        self.cfg = self._pack(np.zeros(0, np.int64))

    def _pack(self, hold_rows: np.ndarray) -> np.ndarray:
        return pack_config(self._head, *self._tail, hold_rows)

    def set_hold_rows(self, rows: np.ndarray) -> None:
        """The constraint rows of the holding constraints (3 per constraint)."""
        base = self.cfg[C_WARN_BASE]
        self.cfg = self._pack(rows)
        self.cfg[C_WARN_BASE] = base

    def set_warning_base(self, count: int) -> None:
        """The fatal warnings' count that the divergence check compares with."""
        self.cfg[C_WARN_BASE] = count

    def contacts(self) -> np.ndarray:
        """The contact structs (call when the step has contacts): the arena, the contact structs'
        layout taken from the bindings at the first call."""
        if not self.layout_known:
            c = self._data.contact
            base = _address(c.dist)
            stride = c.dist.strides[0]
            if base != _address(self.arena):
                raise RuntimeError("unexpected MuJoCo contact layout (contacts not at the arena's start)")

            def off(a: np.ndarray, unit: int) -> int:
                delta = _address(a) - base
                if delta % unit or stride % unit:
                    raise RuntimeError("unexpected MuJoCo contact layout")
                return delta // unit

            self._head[C_LAYOUT:C_HEAD] = (
                stride // 8, off(c.dist, 8), off(c.pos, 8), off(c.frame, 8), stride // 4, off(c.dim, 4),
                off(c.geom, 4), off(c.flex, 4), off(c.elem, 4), off(c.vert, 4), off(c.efc_address, 4),
            )
            self.cfg[C_LAYOUT:C_HEAD] = self._head[C_LAYOUT:C_HEAD]
            self.layout_known = True
        return self.arena


def _struct_fields(data: mujoco.MjData) -> list[int]:
    """Where ``ncon``, ``ne``, ``nefc`` (int32 units), ``time`` and the ``arena`` and ``efc_force``
    pointers (int64 units) lie in the ``mjData`` struct, found by their values: each count set to two
    marks in turn (then restored) and ``time`` likewise, between the warning structs and the end of
    the struct's header; the pointers after it, word by word up to ``efc_force`` (whose address the
    bindings give; ``arena`` is the word before ``qpos``, mjdata.h's order, checked to hold
    ``efc_force``). Raises RuntimeError when a field is not found exactly once."""
    base = data._address
    start = (_address(data.warning.number) - base) // 8
    timers = data.timer.duration  # after the warnings; then the counts and time (about 30 fields)
    words = (_address(timers) + timers.strides[0] * len(timers) - base) // 8 + 64

    def header() -> np.ndarray:
        return np.ctypeslib.as_array((ctypes.c_int64 * words).from_address(base)).copy()

    def find(name: str, marks: tuple[float, float], dtype: type) -> int:
        old = getattr(data, name)
        seen = []
        try:
            for mark in marks:
                setattr(data, name, mark)
                seen.append(set(np.nonzero(header().view(dtype) == mark)[0].tolist()))
        finally:
            setattr(data, name, old)
        got = [i for i in seen[0] & seen[1] if i >= (start if dtype is np.float64 else 2 * start)]
        if len(got) != 1:
            raise RuntimeError(f"unexpected MuJoCo data layout (mjData.{name})")
        return got[0]

    counts = [find(name, (0x5A5A1234, 0x2B3C4D5E), np.int32) for name in ("ncon", "ne", "nefc")]
    t = find("time", (1234.56789e7, -9876.54321e-7), np.float64)
    qpos, efc = _address(data.qpos), _address(data.efc_force)
    word = ctypes.c_int64
    seen_qpos, k = -1, t + 1
    while int(word.from_address(base + 8 * k).value) != efc:
        if k < t + 8 and int(word.from_address(base + 8 * k).value) == qpos:
            seen_qpos = k  # mjData's buffer pointer may hold qpos's address too: the last one
        k += 1
        if k > t + 4096:
            raise RuntimeError("unexpected MuJoCo data layout (mjData.efc_force)")
    arena = int(word.from_address(base + 8 * (seen_qpos - 1)).value)
    if seen_qpos < 0 or not arena <= efc < arena + int(data.narena):
        raise RuntimeError("unexpected MuJoCo data layout (mjData.arena)")
    return [*counts, t, seen_qpos - 1, k]


def _address(a: np.ndarray) -> int:
    return int(a.__array_interface__["data"][0])
