"""Raw contacts of the rod, read from MuJoCo's arrays once per step (no per-contact Python objects).

Frames and units: world frame, metres, newtons. A contact's ``normal`` points from the obstacle toward
the rod; its normal force is decoded as ``mj_contactForce`` does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np


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

    ``point``/``segment``: -1 where MuJoCo does not report a vertex/element; ``geom``: MuJoCo geom id;
    ``obj``: index into ``names[0]`` (object names); ``names[1]``: geom names by ``geom`` id.
    ``self_pairs``: (k, 2) touching segment pairs of the rod itself.
    """

    point: np.ndarray
    segment: np.ndarray
    geom: np.ndarray
    obj: np.ndarray
    piece: np.ndarray
    dist: np.ndarray
    normal: np.ndarray
    pos: np.ndarray
    force: np.ndarray
    active: np.ndarray
    self_pairs: np.ndarray
    names: tuple[tuple[str, ...], dict[int, str]]

    def __len__(self) -> int:
        return len(self.dist)

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
            for i in range(len(self.dist))
        )


_NO_PAIRS = np.zeros((0, 2), int)
_PYRAMIDAL = int(mujoco.mjtCone.mjCONE_PYRAMIDAL)
_EDGES = [np.arange(2 * (k - 1)) for k in range(7)]  # a pyramidal cone's edge rows, by contact dim

_EMPTY_CONTACTS = ContactArrays(
    point=np.zeros(0, int),
    segment=np.zeros(0, int),
    geom=np.zeros(0, int),
    obj=np.zeros(0, int),
    piece=np.zeros(0, int),
    dist=np.zeros(0),
    normal=np.zeros((0, 3)),
    pos=np.zeros((0, 3)),
    force=np.zeros(0),
    active=np.zeros(0, bool),
    self_pairs=np.zeros((0, 2), int),
    names=((), {}),
)



def read_contact_arrays(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    flex_id: int,
    piece_of_geom: np.ndarray,
    obj_of_geom: np.ndarray,
    names: tuple[tuple[str, ...], dict[int, str]],
) -> ContactArrays:
    """Raw rod contacts of the current step as arrays (vectorised; no per-contact Python objects).

    ``piece_of_geom`` / ``obj_of_geom``: per MuJoCo geom id, the obstacle piece index and object index
    (-1 for geoms that are not obstacle pieces); ``names``: see :class:`ContactArrays`.
    """
    d, f = data, flex_id
    nc = int(d.ncon)
    if nc == 0:
        return _EMPTY_CONTACTS
    c = d.contact
    flex = c.flex[:nc]
    geom = c.geom[:nc]
    gid = geom[:, 0]
    rows: Any
    side: Any
    if (flex[:, 1] == f).all() and (gid >= 0).all() and (piece_of_geom[gid] >= 0).all():
        # the usual case: every contact has an obstacle piece as side 0 and the rod as side 1
        rows, side, self_pairs = slice(None), 1, _NO_PAIRS
        normal = c.frame[:, :3].copy()
    else:
        selfm = (flex[:, 0] == f) & (flex[:, 1] == f)
        side1 = (flex[:, 1] == f) & (geom[:, 0] >= 0)  # obstacle is geom[0], rod is side 1
        side0 = (flex[:, 0] == f) & (geom[:, 1] >= 0) & ~side1
        sel = np.nonzero(side0 | side1)[0]
        s1 = side1[sel]
        gid = np.where(s1, geom[sel, 0], geom[sel, 1])
        known = piece_of_geom[gid] >= 0
        rows, s1, gid = sel[known], s1[known], gid[known]
        side = np.where(s1, 1, 0)
        sign = np.where(s1, 1.0, -1.0)[:, None]  # frame normal points from side 0 toward side 1
        normal = sign * c.frame[rows, :3]
        self_pairs = np.sort(c.elem[:nc][selfm], axis=1).astype(int)
    adr = c.efc_address[rows]
    act = adr >= 0
    return ContactArrays(
        point=c.vert[rows, side].astype(int),
        segment=c.elem[rows, side].astype(int),
        geom=gid.astype(int),
        obj=obj_of_geom[gid],
        piece=piece_of_geom[gid],
        dist=c.dist[rows].copy(),
        normal=normal,
        pos=c.pos[rows].copy(),
        force=normal_forces(model, data, c.dim[rows], adr, act),
        active=act,
        self_pairs=self_pairs,
        names=names,
    )


def normal_forces(
    model: mujoco.MjModel, data: mujoco.MjData, dims: np.ndarray, adr: np.ndarray, act: np.ndarray
) -> np.ndarray:
    """Normal force (N) of contacts with constraint rows at ``adr`` (0 where not ``act``ive), as
    ``mj_contactForce`` decodes it: with pyramidal cones the sum of the 2*(dim-1) edge forces."""
    ef = data.efc_force
    every = len(adr) > 0 and bool(act.all())  # the usual: every contact has constraint rows
    if not every and not act.any():
        return np.zeros(len(adr))
    dims, a = (dims, adr) if every else (dims[act], adr[act])
    k = int(dims[0])
    if model.opt.cone != _PYRAMIDAL:
        f = ef[a]
    elif k > 1 and (dims == k).all():
        f = ef[a[:, None] + _EDGES[k]].sum(axis=1)
    else:
        f = np.array(
            [
                float(ef[i : i + 2 * (n - 1)].sum()) if n > 1 else float(ef[i])
                for i, n in zip(a, dims, strict=True)
            ]
        )
    if every:
        return f
    force = np.zeros(len(adr))
    force[act] = f
    return force
