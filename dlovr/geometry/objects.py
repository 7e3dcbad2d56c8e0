"""Environment objects in the world frame: mesh, named faces, convex pieces and the edge table
(which faces meet, convex or concave, and their free-space opening angle)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import trimesh

from dlovr.cache import slow_step
from dlovr.geometry.decomposition import decompose
from dlovr.geometry.faces import object_faces
from dlovr.geometry.mesh import SLOW_TRIANGLES, object_local_mesh
from dlovr.geometry.pieces import Piece, _build_piece

if TYPE_CHECKING:
    from dlovr.scene import Scene


@dataclass(frozen=True)
class EdgeInfo:
    """An edge of an object: two faces meeting, convex or concave, free-space opening angle."""

    a: str
    b: str
    convex: bool
    opening_deg: float
    length: float


@dataclass
class GeomObject:
    """An environment object in the world frame: mesh, named faces, convex pieces, edge table."""

    name: str
    mesh: trimesh.Trimesh  # world frame
    face_names: list[str]
    face_normals: np.ndarray  # (k,3) world
    face_offsets: np.ndarray  # (k,)
    face_tris: list[np.ndarray]  # world triangles (t,3,3) per face
    face_areas: np.ndarray
    pieces: list[Piece]
    edges: list[EdgeInfo]
    approximate: bool

    def face_index(self, name: str) -> int:
        return self.face_names.index(name)


def _edge_table(mesh: trimesh.Trimesh, tri_face: np.ndarray, names: list[str]) -> list[EdgeInfo]:
    adj = mesh.face_adjacency
    if len(adj) == 0:
        return []
    v = mesh.vertices
    n = mesh.face_normals
    h = np.einsum(
        "ek,ek->e", v[mesh.face_adjacency_unshared[:, 1]] - v[mesh.faces[adj[:, 0], 0]], n[adj[:, 0]]
    )
    edges = mesh.face_adjacency_edges
    lengths = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    acc: dict[tuple[int, int], list] = {}
    for k, (i, j) in enumerate(adj):
        fa, fb = int(tri_face[i]), int(tri_face[j])
        if fa == fb:
            continue
        key = (min(fa, fb), max(fa, fb))
        alpha = float(np.degrees(np.arccos(np.clip(n[i] @ n[j], -1.0, 1.0))))
        e = acc.setdefault(key, [0.0, 0.0, 0.0])
        e[0] += lengths[k]
        e[1] += (1.0 if h[k] <= 0 else -1.0) * lengths[k]
        e[2] = alpha
    out = []
    for (fa, fb), (length, convexity, alpha) in sorted(acc.items()):
        convex = convexity >= 0
        out.append(
            EdgeInfo(
                names[fa], names[fb], bool(convex), 180.0 + alpha if convex else 180.0 - alpha, float(length)
            )
        )
    return out


def build_object(
    name: str,
    local_mesh: trimesh.Trimesh,
    transform: np.ndarray | None = None,
    *,
    use_cache: bool = True,
    pieces: tuple[list[np.ndarray], bool] | None = None,
) -> GeomObject:
    """An object from its mesh in its own frame and its pose (4x4). Face names from the local frame.

    ``pieces``: its convex decomposition (local frame, approximate?) if already known (e.g. the one a
    recording was made with); else :func:`decompose` computes it.
    """
    n = len(local_mesh.faces)
    if n <= SLOW_TRIANGLES:
        return _build_object(name, local_mesh, transform, use_cache=use_cache, pieces=pieces)
    with slow_step(f"faces and convex pieces of object {name!r} ({n:,} triangles)"):
        return _build_object(name, local_mesh, transform, use_cache=use_cache, pieces=pieces)


def _build_object(
    name: str,
    local_mesh: trimesh.Trimesh,
    transform: np.ndarray | None,
    *,
    use_cache: bool,
    pieces: tuple[list[np.ndarray], bool] | None,
) -> GeomObject:
    transform = np.eye(4) if transform is None else np.asarray(transform, dtype=float)
    faces = object_faces(local_mesh)
    pieces_local, approximate = pieces if pieces is not None else decompose(local_mesh, use_cache=use_cache)
    rot, trans = transform[:3, :3], transform[:3, 3]
    world = local_mesh.copy()
    world.apply_transform(transform)
    tri_face = np.empty(len(local_mesh.faces), dtype=int)
    names, normals, offsets, tris_list, areas = [], [], [], [], []
    for k, f in enumerate(faces):
        tri_face[f.triangles] = k
        nm = f"{name}.F{f.index}"
        nw = rot @ f.normal
        tris = world.triangles[f.triangles]
        names.append(nm)
        normals.append(nw)
        offsets.append(float(nw @ (rot @ f.centroid + trans)))
        tris_list.append(tris)
        areas.append(f.area)
    obj_faces = list(zip(names, normals, offsets, tris_list, strict=True))
    built = [
        _build_piece(name, i, p @ rot.T + trans, approximate, obj_faces) for i, p in enumerate(pieces_local)
    ]
    edges = _edge_table(local_mesh, tri_face, names)
    return GeomObject(
        name,
        world,
        names,
        np.array(normals),
        np.array(offsets),
        tris_list,
        np.array(areas),
        built,
        edges,
        approximate,
    )


def scene_pieces(scene: Scene, *, use_cache: bool = True) -> dict[str, tuple[list[np.ndarray], bool]]:
    """The convex decomposition of every object of a scene: name -> (pieces in the local frame,
    approximate?). The simulator and the geometry must use the same one (piece k is MuJoCo's geom
    ``<obj>.P<k>``), and a recording keeps it so that replay does not depend on the algorithm."""
    return {o.name: decompose(object_local_mesh(o), use_cache=use_cache) for o in scene.objects}
