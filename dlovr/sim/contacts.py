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
)  # fmt: skip


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


def contact_layout(data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MuJoCo's contact structs as flat arrays, to be read in place by the kernels: a float64 and an
    int32 view of ``data``'s arena and the layout (row strides and field offsets in their units,
    indexed by ``dlovr.sim.kernels.L_*``).

    MuJoCo keeps the contacts at the start of the arena (``d->contact = d->arena``) for the life of
    ``data``, so the views stay valid while ``data`` lives; the field offsets come from the bindings'
    own views, so they follow MuJoCo's struct layout. Call with at least one contact present (the
    bindings give an empty contact list no address).
    """
    c = data.contact
    base = c.dist.__array_interface__["data"][0]
    stride = c.dist.strides[0]

    def off(a: np.ndarray, unit: int) -> int:
        delta = a.__array_interface__["data"][0] - base
        if delta % unit or stride % unit:
            raise RuntimeError("unexpected MuJoCo contact layout")
        return delta // unit

    layout = np.array(
        [stride // 8, off(c.dist, 8), off(c.pos, 8), off(c.frame, 8), stride // 4, off(c.dim, 4),
         off(c.geom, 4), off(c.flex, 4), off(c.elem, 4), off(c.vert, 4), off(c.efc_address, 4)],
        dtype=np.int64,
    )  # fmt: skip
    size = int(data.narena)
    floats = np.ctypeslib.as_array((ctypes.c_double * (size // 8)).from_address(base))
    return floats, floats.view(np.int32), layout
