"""Classification of cable points into environment primitives: every (point, piece) pair within
reach (closest point, distance, active faces by a *tangential* tolerance), computed by the kernels of
:mod:`dlovr.geometry.kernels`; :func:`primitives_per_point` turns the hits into the model's
primitives."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dlovr.geometry import kernels
from dlovr.geometry.packing import PackedPieces, pack_pieces
from dlovr.geometry.pieces import Piece
from dlovr.model.topology import EnvPrimitive

if TYPE_CHECKING:
    from dlovr.geometry.objects import GeomObject

_NO_THRESHOLDS = np.zeros(0)


@dataclass
class PointHit:
    """A cable point near a convex piece: closest point, signed distance, active real face names."""

    point: int
    piece: Piece
    closest: np.ndarray
    distance: float
    faces: tuple[str, ...]


def primitives_per_point(n_points: int, hits: Iterable[PointHit]) -> list[list[EnvPrimitive]]:
    """Environment primitives of every point from its hits (:func:`point_primitives`)."""
    faces: list[list[tuple[str, ...]]] = [[] for _ in range(n_points)]
    for h in hits:
        faces[h.point].append(h.faces)
    made: dict[tuple[str, ...], EnvPrimitive] = {}
    return [point_primitives(f, made) for f in faces]


def point_primitives(
    faces: Iterable[tuple[str, ...]], made: dict[tuple[str, ...], EnvPrimitive]
) -> list[EnvPrimitive]:
    """Environment primitives of one point from the face names of its hits (one per piece; a
    primitive whose faces are a subset of another's at the same point adds nothing and is dropped).
    ``made``: primitives already made, by face names (filled in)."""
    s = set()
    for f in faces:
        e = made.get(f)
        if e is None:
            e = made[f] = EnvPrimitive("faces", f)
        s.add(e)
    if len(s) > 1:
        return sorted(e for e in s if not any(o != e and set(e.faces) < set(o.faces) for o in s))
    return list(s)


class _Classifier:
    """Point classification of :class:`~dlovr.geometry.SceneGeometry` (a mixin; the attributes are
    set by its ``__init__``): which pieces a cable point touches, with which faces. The work is done
    by the compiled kernels of :mod:`dlovr.geometry.kernels` on the pieces packed once
    (:meth:`packed`)."""

    objects: list[GeomObject]
    pieces: list[Piece]
    radius: float
    _piece_ids: dict[tuple[str, int], int] | None
    _packed: PackedPieces | None
    _face_rows: dict[bytes, tuple[str, ...]]

    def packed(self) -> PackedPieces:
        """The pieces packed for the kernels (built on first use)."""
        if self._packed is None:
            self._packed = pack_pieces(self.pieces, [o.name for o in self.objects])
        return self._packed

    def piece_id(self, obj: str, index: int) -> int:
        """Position of piece ``index`` of object ``obj`` in :attr:`pieces`."""
        if self._piece_ids is None:
            self._piece_ids = {(p.obj, p.index): k for k, p in enumerate(self.pieces)}
        return self._piece_ids[(obj, index)]

    def face_tuple(self, row: np.ndarray) -> tuple[str, ...]:
        """The face names of a kernel hit's face-id row (sorted ids, -1 padded)."""
        key = row.tobytes()
        names = self._face_rows.get(key)
        if names is None:
            table = self.packed().face_names
            names = self._face_rows[key] = tuple(table[int(i)] for i in row.tolist() if i >= 0)
        return names

    def _inside_other(self, q: np.ndarray, obj: str, margin: float) -> np.ndarray:
        """(m,) True where q lies inside (deeper than ``margin``) a piece of an object other than ``obj``."""
        pk = self.packed()
        q = np.ascontiguousarray(q, dtype=float).reshape(-1, 3)
        out = np.zeros(len(q), dtype=bool)
        obj_index = [o.name for o in self.objects].index(obj)
        kernels.inside_other_points(pk.floats, pk.ints, q, obj_index, float(margin), out)
        return out

    # ---------------------------------------------------------------- classification
    def classify_points(
        self,
        points: np.ndarray,
        radius: float | None = None,
        contact_tol: float = 5e-4,
        tangential_tol: float | None = None,
    ) -> list[PointHit]:
        """Every (point, piece) pair in contact: centerline within ``radius + contact_tol`` of the piece.

        Active faces are the faces of the closest feature and of every piece edge within
        ``tangential_tol`` (default ``radius / 5``) of the closest point; internal faces, the internal
        part of mixed faces and covered faces are dropped. Pairs left with no face are not reported.
        Sorted by point, then object name and piece index.
        """
        pts = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
        r = self.radius if radius is None else float(radius)
        ttol = r / 5.0 if tangential_tol is None else float(tangential_tol)
        pk = self.packed()
        every = np.arange(len(pts), dtype=np.int64)
        hit_i = np.empty((len(pts) * max(len(self.pieces), 1), 2 + pk.width), np.int64)
        hit_f = np.empty((len(hit_i), 4))
        h = kernels.pair_hits(
            pk.floats, pk.ints, pts, every, every, r, self.radius, float(contact_tol), ttol, _NO_THRESHOLDS,
            False, True, hit_i, hit_f, np.empty(len(pts)), np.empty((0, 6)),
        )
        hits = [
            PointHit(int(hit_i[j, 0]), self.pieces[int(hit_i[j, 1])], hit_f[j, 1:].copy(), float(hit_f[j, 0]),
                     self.face_tuple(hit_i[j, 2:]))
            for j in range(h)
        ]
        hits.sort(key=lambda h: (h.point, h.piece.obj, h.piece.index))
        return hits

    def point_primitives(
        self,
        points: np.ndarray,
        radius: float | None = None,
        contact_tol: float = 5e-4,
        tangential_tol: float | None = None,
    ) -> list[list[EnvPrimitive]]:
        """For each point, the environment primitives it touches (one per piece, duplicates merged)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        return primitives_per_point(len(pts), self.classify_points(pts, radius, contact_tol, tangential_tol))
