"""An object's faces: coplanar edge-connected triangle groups, numbered ``F1…Fk`` deterministically
from the object's own surface in its local frame (pose-independent)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from dlovr.transforms import units

_ANGLE_TOL = 1e-5  # rad: triangles whose normals differ less are coplanar (one face)


@dataclass(frozen=True)
class ObjectFace:
    """A face of an object: coplanar edge-connected triangles. Local frame of the object."""

    index: int  # k of F<k>
    normal: np.ndarray  # outward unit normal, local frame
    offset: float  # n·x = offset on the face's plane
    triangles: np.ndarray  # triangle indices into the mesh
    area: float
    centroid: np.ndarray


def _clean(v: float) -> float:
    return float(v) + 0.0  # turn -0.0 into 0.0


def object_faces(mesh: trimesh.Trimesh) -> list[ObjectFace]:
    """Faces of a watertight mesh: coplanar edge-connected triangle groups, numbered stably.

    The numbering depends only on the geometry (normals, planes, centroids) in the mesh's own frame:
    faces are sorted by normal (top first), then plane offset, then centroid.
    """
    nt = len(mesh.faces)
    parent = np.arange(nt)

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    adj = mesh.face_adjacency
    if len(adj):
        ang = mesh.face_adjacency_angles
        for (i, j), a in zip(adj, ang, strict=True):
            if a < _ANGLE_TOL:
                ri, rj = find(int(i)), find(int(j))
                if ri != rj:
                    parent[max(ri, rj)] = min(ri, rj)
    roots = np.array([find(i) for i in range(nt)])
    tri_area = mesh.area_faces
    tri_cent = mesh.triangles_center
    groups = []
    for r in np.unique(roots):
        tris = np.nonzero(roots == r)[0]
        w = tri_area[tris]
        n = units((mesh.face_normals[tris] * w[:, None]).sum(axis=0))
        area = float(w.sum())
        cen = (tri_cent[tris] * w[:, None]).sum(axis=0) / max(area, 1e-300)
        off = float(n @ cen)
        groups.append((n, off, tris, area, cen))

    def key(g: tuple) -> tuple:
        n, off, _, _, cen = g
        return (
            -_clean(round(n[2], 6)),
            -_clean(round(n[1], 6)),
            -_clean(round(n[0], 6)),
            _clean(round(off, 7)),
            *(_clean(round(c, 7)) for c in cen),
        )

    groups.sort(key=key)
    return [ObjectFace(k + 1, g[0], g[1], g[2], g[3], g[4]) for k, g in enumerate(groups)]
