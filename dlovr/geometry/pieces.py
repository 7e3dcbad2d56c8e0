"""Convex pieces of an object in the world frame: half-spaces, face polygons labelled external,
internal or mixed against the object's named faces, and the piece's edges."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

import numpy as np

from dlovr.geometry.vectors import _clip_polygon, _polygon_area
from dlovr.transforms import units

FaceLabel = Literal["external", "internal", "mixed"]


@dataclass
class PieceFace:
    """One planar face of a convex piece (world frame)."""

    normal: np.ndarray
    offset: float
    polygon: np.ndarray  # (k,3) ordered loop
    label: FaceLabel
    face: str | None  # object face name (None for internal faces)
    exposed: np.ndarray  # (t,3,3) triangles of the object face in this plane (world), for mixed faces
    exposed_area: float = 0.0  # area of the part on the object's surface


@dataclass
class Piece:
    """A convex piece of an object: half-spaces ``normals @ x <= offsets`` (world frame)."""

    obj: str
    index: int
    approximate: bool
    vertices: np.ndarray
    faces: list[PieceFace]
    normals: np.ndarray  # (F,3)
    offsets: np.ndarray  # (F,)
    edge_a: np.ndarray  # (E,3)
    edge_b: np.ndarray  # (E,3)
    edge_faces: np.ndarray  # (E,2) indices into faces
    lo: np.ndarray
    hi: np.ndarray

    @property
    def volume(self) -> float:
        from scipy.spatial import ConvexHull

        return float(ConvexHull(self.vertices).volume)

    @property
    def area(self) -> float:
        return float(sum(_polygon_area(f.polygon) for f in self.faces))


def _hull_planes(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], np.ndarray]:
    """Merged facet planes of the convex hull of ``vertices``: normals, offsets, polygons, hull vertices."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(vertices)
    pts = vertices[hull.vertices]
    scale = float(np.ptp(pts, axis=0).max()) or 1.0
    normals: list[np.ndarray] = []
    offsets: list[float] = []
    kept_n = np.empty((len(hull.equations), 3))  # the normals and offsets kept so far, as arrays:
    kept_d = np.empty(len(hull.equations))  # one comparison per facet, not a loop (a mesh's hull
    for eq in hull.equations:  # has thousands of facets)
        n, d = eq[:3], -eq[3]
        nn = float(np.linalg.norm(n))
        n, d = n / nn, d / nn
        k = len(normals)
        if k and np.any(((kept_n[:k] * n).sum(axis=1) > 1 - 1e-12) & (np.abs(d - kept_d[:k]) < 1e-9 * scale)):
            continue
        kept_n[k], kept_d[k] = n, d
        normals.append(n)
        offsets.append(d)
    polys = []
    for n, d in zip(normals, offsets, strict=True):
        on = pts[np.abs(pts @ n - d) < 1e-9 * scale]
        c = on.mean(axis=0)
        u = units(on[0] - c) if np.linalg.norm(on[0] - c) > 0 else units(np.cross(n, [1.0, 0, 0]))
        w = np.cross(n, u)
        ang = np.arctan2((on - c) @ w, (on - c) @ u)
        polys.append(on[np.argsort(ang)])
    return np.array(normals), np.array(offsets), polys, pts


def _face_pairs(on_face: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs ``i < j`` of faces sharing two vertices or more, in the order of a loop over ``i``
    then ``j``. ``on_face``: (faces, vertices) booleans. A sparse product: a mesh's hull has thousands
    of faces of three vertices each (a dense one was 67 GFLOP for a 5,120-triangle sphere)."""
    from scipy import sparse

    inc = sparse.csr_matrix(on_face.astype(np.int32))
    together = sparse.triu(inc @ inc.T, k=1).tocoo()
    keep = together.data >= 2
    i, j = together.row[keep], together.col[keep]
    order = np.lexsort((j, i))
    return i[order], j[order]


def _piece_edges(
    pts: np.ndarray, normals: np.ndarray, offsets: np.ndarray, scale: float
) -> tuple[list[np.ndarray], list[np.ndarray], list[tuple[int, int]]]:
    """The edges of a convex piece: for each pair of faces sharing two hull vertices, its two ends
    (the extreme shared vertices along the edge's direction) and the pair."""
    ea, eb, ef = [], [], []
    on_face = np.array(  # one face at a time, as before (a matrix product could round otherwise)
        [np.abs(pts @ n - d) < 1e-9 * scale for n, d in zip(normals, offsets, strict=True)], dtype=bool
    ).reshape(len(normals), len(pts))
    first, second = _face_pairs(on_face)
    directions = units(np.cross(normals[first], normals[second]))  # row by row as one at a time
    for i, j, e in zip(first, second, directions, strict=True):
        shared = pts[on_face[i] & on_face[j]]
        if len(shared) >= 2:
            s = shared @ e
            ea.append(shared[int(np.argmin(s))])
            eb.append(shared[int(np.argmax(s))])
            ef.append((int(i), int(j)))
    return ea, eb, ef


def _coplanar(
    normals: np.ndarray, offsets: np.ndarray, obj_n: np.ndarray, obj_d: np.ndarray, scale: float
) -> Iterator[np.ndarray]:
    """For each piece face (``normals``, ``offsets``), the indices of the object faces in its plane:
    normals within 1e-9 of each other, offsets within 1e-7 x ``scale``. Computed for a block of
    faces at once (a mesh's hull has thousands), each dot product summed as for one face."""
    block = max(1, 4_000_000 // max(1, 3 * len(obj_n)))
    for s in range(0, len(normals), block):
        n, d = normals[s : s + block], offsets[s : s + block]
        dots = (n[:, None, :] * obj_n[None, :, :]).sum(axis=2)
        same = (dots >= 1 - 1e-9) & (np.abs(d[:, None] - obj_d[None, :]) <= 1e-7 * scale)
        yield from (np.flatnonzero(row) for row in same)


def _build_piece(
    obj: str,
    index: int,
    vertices: np.ndarray,
    approximate: bool,
    obj_faces: list[tuple[str, np.ndarray, float, np.ndarray]],
) -> Piece:
    """Convex piece from world-frame vertices; faces labelled against the object's faces.

    ``obj_faces``: (name, world normal, world offset, world triangles (t,3,3)) for each object face.
    """
    normals, offsets, polys, pts = _hull_planes(vertices)
    scale = float(np.ptp(pts, axis=0).max()) or 1.0
    faces: list[PieceFace] = []
    obj_n = np.array([f[1] for f in obj_faces], dtype=float).reshape(-1, 3)
    obj_d = np.array([f[2] for f in obj_faces], dtype=float)
    for n, d, poly, same in zip(normals, offsets, polys, _coplanar(normals, offsets, obj_n, obj_d, scale),
                                strict=True):
        area = _polygon_area(poly)
        best_name, best_overlap, best_tris = None, 0.0, np.zeros((0, 3, 3))
        for k in same:
            name, _, _, tris = obj_faces[k]
            ov = sum(_polygon_area(_clip_polygon(poly, t, n)) for t in tris)
            if ov > best_overlap:
                best_name, best_overlap, best_tris = name, ov, tris
        if best_name is None or best_overlap <= 1e-7 * area:
            label: FaceLabel = "internal"
            best_name = None
        elif best_overlap >= (1 - 1e-7) * area:
            label = "external"
        else:
            label = "mixed"
        faces.append(
            PieceFace(n, float(d), poly, label, best_name, best_tris, float(min(best_overlap, area)))
        )
    ea, eb, ef = _piece_edges(pts, normals, offsets, scale)
    return Piece(
        obj,
        index,
        approximate,
        pts,
        faces,
        normals,
        offsets,
        np.array(ea).reshape(-1, 3),
        np.array(eb).reshape(-1, 3),
        np.array(ef, dtype=int).reshape(-1, 2),
        pts.min(axis=0),
        pts.max(axis=0),
    )
