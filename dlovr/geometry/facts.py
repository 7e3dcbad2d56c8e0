"""Face facts of a scene (:class:`~dlovr.model.discrete.FactBook`): face normals, and for face pairs
concave or convex and the free-space opening angle, computed on demand from the geometry."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from dlovr.geometry.classify import _Classifier
from dlovr.geometry.vectors import _points_in_triangles
from dlovr.model.discrete import ContactFacts, FaceFact, FactBook, PairFact
from dlovr.model.topology import Contact, Vec3, as_vec3
from dlovr.transforms import units

if TYPE_CHECKING:
    from dlovr.geometry.objects import GeomObject


class SceneFactBook(FactBook):
    """FactBook of a scene: every object face, and pair facts computed on demand from the geometry."""

    def __init__(self, geom: _PairFacts):
        faces = {
            n: FaceFact(n, o.name, as_vec3(o.face_normals[k]))
            for o in geom.objects
            for k, n in enumerate(o.face_names)
        }
        super().__init__(faces, [])
        self._geom = geom

    def pair(self, a: str, b: str) -> PairFact:
        key = frozenset((a, b))
        if key not in self.pairs:
            self.pairs[key] = self._geom.pair_fact(a, b)
        return self.pairs[key]

    def for_contact(self, contact: Contact, dlo_vector: Vec3 | None = None) -> ContactFacts:
        names = [f for f in contact.faces if f in self.faces]
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                self.pair(a, b)
        return super().for_contact(contact, dlo_vector)


class _PairFacts(_Classifier):
    """Face facts of :class:`~dlovr.geometry.SceneGeometry` (a mixin; the attributes are set by its
    ``__init__``): the fact book and the facts of face pairs."""

    _face_owner: dict[str, tuple[GeomObject, int]]
    _book: SceneFactBook | None

    # ---------------------------------------------------------------- facts
    def fact_book(self) -> SceneFactBook:
        """FaceFact for every object face; PairFacts computed (and cached) on demand."""
        if self._book is None:
            self._book = SceneFactBook(self)
        return self._book

    def pair_fact(self, a: str, b: str) -> PairFact:
        """Concave/convex and free-space opening angle of two faces (any objects), docs/model.md 3.2.

        From the closest points of the two faces, probe in-plane toward the other face's outward side
        (a distance of the DLO radius): the pair is concave iff both faces continue there, exposed.
        """
        oa, ka = self._face_owner[a]
        ob, kb = self._face_owner[b]
        na, nb = oa.face_normals[ka], ob.face_normals[kb]
        cosang = float(np.clip(na @ nb, -1.0, 1.0))
        alpha = float(np.degrees(np.arccos(cosang)))
        cross = np.cross(na, nb)
        crease = as_vec3(units(cross)) if np.linalg.norm(cross) > 1e-9 else None
        if np.linalg.norm(cross) <= 1e-12:
            # parallel (same side: one plane; opposite: facing walls, a slot): treat as concave
            return PairFact(a, b, True, 180.0 - alpha, None)
        ta, tb = oa.face_tris[ka], ob.face_tris[kb]
        pa, pb = _closest_between_triangle_sets(ta, tb)
        ua = units(nb - cosang * na)
        ub = units(na - cosang * nb)
        s = max(self.radius, 1e-6)
        tol = 1e-9 * max(1.0, float(np.abs(pa).max()))

        def continues(pt: np.ndarray, u: np.ndarray, tris: np.ndarray, n: np.ndarray, obj: str) -> bool:
            probe = (pt + s * u)[None]
            # also accept a probe a little further in case the closest point is on the face's border
            if not _points_in_triangles(probe, tris, tol)[0]:
                return False
            return not bool(self._inside_other(probe + 2.0 * self.radius * n, obj, 1e-9)[0])

        concave = continues(pa, ua, ta, na, oa.name) and continues(pb, ub, tb, nb, ob.name)
        if not concave:
            # the closest points found may be an end of a shared edge, where the probe leaves the face
            # across a third face's border (a valley closed by a ramp): probe the edge's middle too
            ma, mb = _shared_edge_middle(pa, pb, ta, tb, na, nb, cross)
            if ma is not pa:
                concave = continues(ma, ua, ta, na, oa.name) and continues(mb, ub, tb, nb, ob.name)
        opening = 180.0 - alpha if concave else 180.0 + alpha
        return PairFact(a, b, concave, opening, crease)


def _shared_edge_middle(
    pa: np.ndarray,
    pb: np.ndarray,
    ta: np.ndarray,
    tb: np.ndarray,
    na: np.ndarray,
    nb: np.ndarray,
    crease: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Where two faces meet along an edge, the middle of that edge instead of the closest points found
    (often an end of the edge, where a probe into the face can leave it across a third face's border).
    Faces that do not touch, or whose common points are not one segment lying in both, keep pa, pb."""
    scale = max(1.0, float(np.abs(ta).max()), float(np.abs(tb).max()))
    tol = 1e-9 * scale
    if float(np.linalg.norm(pa - pb)) > tol:
        return pa, pb
    verts = np.concatenate([ta.reshape(-1, 3), tb.reshape(-1, 3)])
    on = (np.abs((verts - pa) @ na) <= tol) & (np.abs((verts - pa) @ nb) <= tol)
    if on.sum() < 2:
        return pa, pb
    c = units(crease)
    t = (verts[on] - pa) @ c
    mid = pa + 0.5 * (t.min() + t.max()) * c
    if _points_in_triangles(mid[None], ta, tol)[0] and _points_in_triangles(mid[None], tb, tol)[0]:
        return mid, mid
    return pa, pb


def _closest_between_triangle_sets(ta: np.ndarray, tb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points between two sets of triangles (vertex-triangle and edge-edge candidates)."""
    best = (np.inf, None, None)

    def vert_tri(vs: np.ndarray, tris: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        # closest points from vertices vs (m,3) to triangles (t,3,3); via face projection or edges
        a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
        n = units(np.cross(b - a, c - a))
        dd = np.einsum("mtk,tk->mt", vs[:, None] - a[None], n)
        proj = vs[:, None] - dd[..., None] * n[None]
        ins = np.ones(dd.shape, dtype=bool)
        for u, v in ((a, b), (b, c), (c, a)):
            ins &= np.einsum("mtk,tk->mt", proj - u[None], np.cross(n, v - u)) >= 0
        dist = np.where(ins, np.abs(dd), np.inf)
        k = np.unravel_index(int(np.argmin(dist)), dist.shape)
        return float(dist[k]), vs[k[0]], proj[k]

    va = ta.reshape(-1, 3)
    vb = tb.reshape(-1, 3)
    d1, p1, q1 = vert_tri(va, tb)
    if d1 < best[0]:
        best = (d1, p1, q1)
    d2, p2, q2 = vert_tri(vb, ta)
    if d2 < best[0]:
        best = (d2, q2, p2)
    # edge-edge: sample-free segment-segment closest points
    sa = np.concatenate([ta[:, [0, 1]], ta[:, [1, 2]], ta[:, [2, 0]]])
    sb = np.concatenate([tb[:, [0, 1]], tb[:, [1, 2]], tb[:, [2, 0]]])
    pa, pb, dd = _segments_closest(sa[:, 0], sa[:, 1], sb[:, 0], sb[:, 1])
    k = np.unravel_index(int(np.argmin(dd)), dd.shape)
    if dd[k] < best[0] - 1e-12:
        best = (float(dd[k]), pa[k], pb[k])
    return np.asarray(best[1]), np.asarray(best[2])


def _segments_closest(a0, a1, b0, b1):
    """Closest points between every segment a (A) and every segment b (B): (A,B,3), (A,B,3), (A,B)."""
    d1 = (a1 - a0)[:, None]
    d2 = (b1 - b0)[None]
    r = a0[:, None] - b0[None]
    a = np.einsum("abk,abk->ab", d1 + 0 * d2, d1 + 0 * d2)
    e = np.einsum("abk,abk->ab", d2 + 0 * d1, d2 + 0 * d1)
    f = np.einsum("abk,abk->ab", d2 + 0 * d1, r)
    c = np.einsum("abk,abk->ab", d1 + 0 * d2, r)
    b = np.einsum("abk,abk->ab", d1 + 0 * d2, d2 + 0 * d1)
    den = a * e - b * b
    safe = np.where(den > 1e-18 * np.maximum(a * e, 1e-300), den, np.inf)
    s = np.clip((b * f - c * e) / safe, 0.0, 1.0)
    t = (b * s + f) / np.where(e > 0, e, 1.0)
    t_c = np.clip(t, 0.0, 1.0)
    s = np.where(t != t_c, np.clip((b * t_c - c) / np.where(a > 0, a, 1.0), 0.0, 1.0), s)
    pa = a0[:, None] + s[..., None] * d1
    pb = b0[None] + t_c[..., None] * d2
    return pa, pb, np.linalg.norm(pa - pb, axis=2)
