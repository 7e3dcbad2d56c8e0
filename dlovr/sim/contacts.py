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
    C_NFATAL,
    C_NGEOM,
    C_NQ,
    C_NV,
    C_NVERT,
    C_PYRAMIDAL,
    C_QPOS,
    C_QVEL,
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

    ``mj``: one float64 view over qpos, qvel and the cable points (they lie in ``data``'s buffer, fixed
    for its life); ``warn``: its warning structs as int32; ``arena``: its contact structs, which
    MuJoCo keeps at the start of the arena (``d->contact = d->arena``) for the life of ``data`` (taken
    at the first contact: the bindings give an empty contact list no address); ``cfg``: the kernel's
    configuration (``dlovr.sim.kernels.C_*``: the warning baseline, the rod's flex id, the cone, where
    the arrays lie in ``mj``, the contact structs' layout from the bindings' own views, the fatal
    warnings, the obstacle piece and object of each geom, the holding constraints' rows). Keep
    ``data`` alive as long as the views.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        xpos: np.ndarray,
        flex: int,
        fatal: np.ndarray,
        piece_of_geom: np.ndarray,
        obj_of_geom: np.ndarray,
    ):
        arrays = (data.qpos, data.qvel, xpos)
        ptrs = [_address(a) for a in arrays]
        lo = min(ptrs)
        hi = max(p + a.nbytes for p, a in zip(ptrs, arrays, strict=True))
        if any((p - lo) % 8 for p in ptrs) or not all(a.flags.c_contiguous for a in arrays):
            raise RuntimeError("unexpected MuJoCo data layout")
        self.mj = np.ctypeslib.as_array((ctypes.c_double * ((hi - lo) // 8)).from_address(lo))
        number = data.warning.number  # every other int32 of the warning structs
        warn = (ctypes.c_int32 * (2 * len(number) - 1)).from_address(_address(number))
        self.warn = np.ctypeslib.as_array(warn)
        self.arena = np.zeros(0)
        self._data = data
        q, v, x = ((p - lo) // 8 for p in ptrs)
        self._head = np.zeros(C_HEAD, np.int64)
        self._head[[C_FLEX, C_PYRAMIDAL, C_NFATAL, C_NGEOM]] = (
            flex, int(model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL), len(fatal), len(piece_of_geom)
        )
        self._head[[C_XPOS, C_QPOS, C_NQ, C_QVEL, C_NV, C_NVERT]] = (
            x, q, len(data.qpos), v, len(data.qvel), len(xpos)
        )
        self._tail = (
            np.asarray(fatal, np.int64) * (number.strides[0] // 4),
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
        """The contact structs (call when the step has contacts)."""
        if len(self.arena) == 0:
            c = self._data.contact
            base = _address(c.dist)
            stride = c.dist.strides[0]

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
            size = int(self._data.narena) // 8
            self.arena = np.ctypeslib.as_array((ctypes.c_double * size).from_address(base))
        return self.arena


def _address(a: np.ndarray) -> int:
    return int(a.__array_interface__["data"][0])
