"""Polygon and triangle helpers of the geometry package (world or local frame, metres); the vector
helpers are :mod:`dlovr.transforms`'s."""

from __future__ import annotations

import numpy as np

from dlovr.transforms import units


def _polygon_area(poly: np.ndarray) -> float:
    if len(poly) < 3:
        return 0.0
    s = np.cross(poly, np.roll(poly, -1, axis=0)).sum(axis=0)
    return 0.5 * float(np.linalg.norm(s))


def _clip_polygon(poly: np.ndarray, tri: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman: part of a convex planar polygon inside a coplanar triangle (3-D)."""
    out = poly
    t_n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    sign = 1.0 if float(t_n @ normal) >= 0 else -1.0
    for i in range(3):
        a, b = tri[i], tri[(i + 1) % 3]
        inward = sign * np.cross(normal, b - a)
        if len(out) == 0:
            break
        s = (out - a) @ inward
        new: list[np.ndarray] = []
        for k in range(len(out)):
            p, q = out[k], out[(k + 1) % len(out)]
            sp, sq = s[k], s[(k + 1) % len(out)]
            if sp >= 0:
                new.append(p)
            if (sp >= 0) != (sq >= 0):
                new.append(p + (q - p) * (sp / (sp - sq)))
        out = np.array(new) if new else np.zeros((0, 3))
    return out


_TRI_FRAMES: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def _tri_frames(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Edge start points (t,3,3) and inward in-plane edge normals (t,3,3) of triangles (cached)."""
    hit = _TRI_FRAMES.get(id(tris))
    if hit is not None and hit[0] is tris:
        return hit[1], hit[2]
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    n = units(np.cross(b - a, c - a))  # (t,3)
    starts, inwards = [], []
    for u, v in ((a, b), (b, c), (c, a)):
        inward = np.cross(n, v - u)
        starts.append(u)
        inwards.append(inward / np.linalg.norm(inward, axis=1, keepdims=True))
    out = (np.stack(starts, axis=1), np.stack(inwards, axis=1))
    if len(_TRI_FRAMES) > 4096:
        _TRI_FRAMES.clear()
    _TRI_FRAMES[id(tris)] = (tris, *out)
    return out


def _points_in_triangles(q: np.ndarray, tris: np.ndarray, tol: float) -> np.ndarray:
    """For points q (m,3) near the plane of coplanar triangles tris (t,3,3): inside any (m,) bool."""
    if len(tris) == 0 or len(q) == 0:
        return np.zeros(len(q), dtype=bool)
    starts, inwards = _tri_frames(tris)
    s = np.einsum("mtek,tek->mte", q[:, None, None, :] - starts[None], inwards)  # (m,t,3)
    return (s >= -tol).all(axis=2).any(axis=1)
