"""Classification of cable points into environment primitives: every (point, piece) pair within
reach (closest point, distance, active faces by a *tangential* tolerance), with the slack of its
decisions; :func:`primitives_per_point` turns the hits into the model's primitives."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dlovr.geometry.pieces import Piece, PieceFace
from dlovr.geometry.vectors import _closest_on_segments, _points_in_triangles
from dlovr.model.topology import EnvPrimitive

if TYPE_CHECKING:
    from dlovr.geometry.objects import GeomObject


@dataclass
class PointHit:
    """A cable point near a convex piece: closest point, signed distance, active real face names."""

    point: int
    piece: Piece
    closest: np.ndarray
    distance: float
    faces: tuple[str, ...]


def primitives_per_point(n_points: int, hits: Iterable[PointHit]) -> list[list[EnvPrimitive]]:
    """Environment primitives of every point from its hits (one per piece; a primitive whose faces
    are a subset of another's at the same point adds nothing and is dropped)."""
    out: list[set[EnvPrimitive]] = [set() for _ in range(n_points)]
    made: dict[tuple[str, ...], EnvPrimitive] = {}
    for h in hits:
        e = made.get(h.faces)
        if e is None:
            e = made[h.faces] = EnvPrimitive("faces", h.faces)
        out[h.point].add(e)
    return [
        sorted(e for e in s if not any(o != e and set(e.faces) < set(o.faces) for o in s))
        if len(s) > 1
        else list(s)
        for s in out
    ]


class _Classifier:
    """Point classification of :class:`~dlovr.geometry.SceneGeometry` (a mixin; the attributes are
    set by its ``__init__``): which pieces a cable point touches, with which faces."""

    objects: list[GeomObject]
    pieces: list[Piece]
    radius: float
    _piece_ids: dict[tuple[str, int], int] | None
    _pad: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None
    _outlines: dict[int, tuple[np.ndarray, np.ndarray]]
    _box: tuple[np.ndarray, np.ndarray] | None

    # ---------------------------------------------------------------- inside / covered tests
    def _inside_other(self, q: np.ndarray, obj: str, margin: float) -> np.ndarray:
        """(m,) True where q lies inside (deeper than ``margin``) a piece of an object other than ``obj``."""
        out = np.zeros(len(q), dtype=bool)
        for p in self.pieces:
            if p.obj == obj:
                continue
            res = q @ p.normals.T - p.offsets
            out |= (res < -margin).all(axis=1)
        return out

    def _exposed(self, pf: PieceFace, obj: str, q: np.ndarray, tol: float) -> np.ndarray:
        """(m,) True where points q on a piece face lie on the object's real, uncovered surface."""
        if pf.label == "internal" or pf.face is None:
            return np.zeros(len(q), dtype=bool)
        ok = np.ones(len(q), dtype=bool)
        if pf.label == "mixed":
            ok &= _points_in_triangles(q, pf.exposed, tol)
        probe = q + 2.0 * self.radius * pf.normal
        ok &= ~self._inside_other(probe, obj, 1e-9)
        return ok

    # ---------------------------------------------------------------- classification
    def piece_id(self, obj: str, index: int) -> int:
        """Position of piece ``index`` of object ``obj`` in :attr:`pieces`."""
        if self._piece_ids is None:
            self._piece_ids = {(p.obj, p.index): k for k, p in enumerate(self.pieces)}
        return self._piece_ids[(obj, index)]

    def _boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounding boxes of all pieces, (P,3) lower and upper corners."""
        if self._box is None:
            self._box = (
                np.array([p.lo for p in self.pieces]).reshape(-1, 3),
                np.array([p.hi for p in self.pieces]).reshape(-1, 3),
            )
        return self._box

    def _padded(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """All pieces' planes padded to one array: normals (P,F,3), offsets (P,F), face names (P,F),
        ``external`` (P,F): the whole piece face lies on the object's surface, and the object index
        of every piece (P,)."""
        if self._pad is None:
            fmax = max((len(p.faces) for p in self.pieces), default=1)
            n = np.zeros((len(self.pieces), fmax, 3))
            d = np.full((len(self.pieces), fmax), 1e9)
            names = np.full((len(self.pieces), fmax), None, dtype=object)
            external = np.zeros((len(self.pieces), fmax), dtype=bool)
            objs = {o.name: i for i, o in enumerate(self.objects)}
            owner = np.array([objs[p.obj] for p in self.pieces], dtype=np.int64)
            for k, p in enumerate(self.pieces):
                for f, pf in enumerate(p.faces):
                    n[k, f], d[k, f], names[k, f] = pf.normal, pf.offset, pf.face
                    external[k, f] = pf.label == "external"
            self._pad = (n, d, names, external, owner)
        return self._pad


    def _probe_residuals(self, probes: np.ndarray, obj_index: np.ndarray) -> np.ndarray:
        """(K,P) largest plane residual of each probe in each piece of another object than
        ``obj_index`` (+inf for the object's own pieces): a probe is inside a piece where it is below
        -1e-9, and it can move by its distance to -1e-9 before that changes."""
        n_all, d_all, _, _, owner = self._padded()
        res = (np.einsum("pfi,ki->kpf", n_all, probes) - d_all[None]).max(axis=2)
        res[owner[None, :] == obj_index[:, None]] = np.inf
        return res

    def _outline_slack(self, pf: PieceFace, q: np.ndarray) -> np.ndarray:
        """(m,) how far points ``q`` on a mixed piece face may move before they cross the outline of
        its exposed part (the triangle edges not shared by two of its triangles), less the
        tolerance of the in-triangle test."""
        key = id(pf)
        if key not in self._outlines:
            count: dict[tuple[tuple[float, ...], tuple[float, ...]], int] = {}
            for tri in np.asarray(pf.exposed).reshape(-1, 3, 3):
                for i in range(3):
                    a, b = tuple(tri[i].tolist()), tuple(tri[(i + 1) % 3].tolist())
                    e = (a, b) if a <= b else (b, a)
                    count[e] = count.get(e, 0) + 1
            outline = [e for e, c in count.items() if c == 1]
            self._outlines[key] = (
                np.array([e[0] for e in outline], dtype=float).reshape(-1, 3),
                np.array([e[1] for e in outline], dtype=float).reshape(-1, 3),
            )
        a, b = self._outlines[key]
        if len(a) == 0:
            return np.zeros(len(q))
        _, d = _closest_on_segments(np.asarray(q, dtype=float).reshape(-1, 3), a, b)
        return np.maximum(d.min(axis=1) - 1e-8, 0.0)

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
        """
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        r = self.radius if radius is None else float(radius)
        ttol = r / 5.0 if tangential_tol is None else float(tangential_tol)
        return self._classify(pts, r, contact_tol, ttol, None)[0]

    def _classify(
        self, pts: np.ndarray, r: float, contact_tol: float, ttol: float, thresholds: tuple[float, ...] | None
    ) -> tuple[list[PointHit], np.ndarray | None]:
        """:meth:`classify_points`, and the slack of its decisions per point over every piece (see
        :meth:`label_slack`) when ``thresholds`` is not ``None``."""
        reach = r + contact_tol
        hits: list[PointHit] = []
        owner = self._padded()[4]  # object index of every piece
        lo_all, hi_all = self._boxes()
        outside_all = np.maximum(
            lo_all[None] - reach - pts[:, None], pts[:, None] - hi_all[None] - reach
        ).max(axis=2)
        inbox = outside_all <= 0  # (m,P): the point lies in the piece's box (+ reach)
        slack = None
        if thresholds is not None:  # outside a box by d (in one coordinate): d to go before it counts
            slack = (
                np.where(inbox, np.inf, outside_all).min(axis=1) if len(lo_all) else np.full(len(pts), np.inf)
            )
        for k in np.nonzero(inbox.any(axis=0))[0].tolist():  # pieces whose box (+ reach) holds a point
            piece = self.pieces[k]
            sel = np.nonzero(inbox[:, k])[0]
            p = pts[sel]
            n, d = piece.normals, piece.offsets
            scale = float(np.ptp(piece.vertices, axis=0).max())
            eps = 1e-9 * max(scale, 1e-3)
            res = p @ n.T - d  # (m,F)
            proj = p[:, None, :] - res[..., None] * n[None]  # (m,F,3)
            pres = np.einsum("mfk,gk->mfg", proj, n) - d[None, None]
            valid = (pres <= eps).all(axis=2)
            inside = (res <= 0).all(axis=1)
            fdist = np.where(valid & (res >= -eps), res, np.inf)
            qe, de = _closest_on_segments(p, piece.edge_a, piece.edge_b)
            m = len(p)
            best_f = np.argmin(fdist, axis=1)
            bf = fdist[np.arange(m), best_f]
            if de.shape[1]:
                best_e = np.argmin(de, axis=1)
                be = de[np.arange(m), best_e]
            else:
                best_e = np.zeros(m, dtype=int)
                be = np.full(m, np.inf)
            use_face = bf <= be
            q = np.where(
                use_face[:, None], proj[np.arange(m), best_f], qe[np.arange(m), best_e] if de.shape[1] else 0
            )
            dist = np.where(use_face, bf, be)
            margin = None
            if slack is not None:  # inside the piece: no bound; else the distance against reach
                maxres = res.max(axis=1)
                margin = np.where(maxres <= 0, 0.0, np.minimum(maxres, np.abs(dist - reach)))
            # inside points: nearest face plane
            if inside.any():
                jin = np.argmax(res, axis=1)
                q = np.where(inside[:, None], proj[np.arange(m), jin], q)
                dist = np.where(inside, res[np.arange(m), jin], dist)
                best_f = np.where(inside, jin, best_f)
                use_face = use_face | inside
            close = dist <= reach
            if not close.any():
                if slack is not None:
                    slack[sel] = np.minimum(slack[sel], margin)
                continue
            idx = np.nonzero(close)[0]
            q, dist, use_face, best_f = q[idx], dist[idx], use_face[idx], best_f[idx]
            active = np.zeros((len(idx), len(piece.faces)), dtype=bool)
            active[np.arange(len(idx))[use_face], best_f[use_face]] = True
            mc = None if margin is None else margin[idx]
            if len(piece.edge_faces):
                _, dq = _closest_on_segments(q, piece.edge_a, piece.edge_b)
                near = dq <= ttol
                for e, (fi, fj) in enumerate(piece.edge_faces):
                    active[:, fi] |= near[:, e]
                    active[:, fj] |= near[:, e]
                if mc is not None:
                    mc = np.minimum(mc, np.abs(dq - ttol).min(axis=1))
            real = np.zeros_like(active)
            for fi, pf in enumerate(piece.faces):
                rows = np.nonzero(active[:, fi])[0]
                if len(rows):
                    real[rows, fi] = self._exposed(pf, piece.obj, q[rows], max(eps, 1e-9))
                    if mc is not None and pf.label != "internal" and pf.face is not None:
                        if pf.label == "mixed":
                            mc[rows] = np.minimum(mc[rows], self._outline_slack(pf, q[rows]))
                        probes = q[rows] + 2.0 * self.radius * pf.normal
                        cover = self._probe_residuals(probes, np.full(len(rows), owner[k]))
                        m_cover = np.abs(cover + 1e-9).min(axis=1) if cover.shape[1] else np.inf
                        mc[rows] = np.minimum(mc[rows], m_cover)
            if slack is not None and margin is not None and mc is not None:
                for t in thresholds or ():
                    mc = np.minimum(mc, np.abs(dist - t))
                margin[idx] = mc
                slack[sel] = np.minimum(slack[sel], margin)
            for j in range(len(idx)):
                names = tuple(sorted({piece.faces[fi].face for fi in np.nonzero(real[j])[0]}))  # type: ignore[type-var]
                if names:
                    hits.append(PointHit(int(sel[idx[j]]), piece, q[j], float(dist[j]), names))  # type: ignore[arg-type]
        hits.sort(key=lambda h: (h.point, h.piece.obj, h.piece.index))
        return hits, slack

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
