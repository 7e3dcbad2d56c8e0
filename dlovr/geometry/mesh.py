"""Meshes: validation (watertight, oriented, not self-intersecting), conversion to and from
manifold3d, primitives (box, prism) and a scene object's mesh in its own frame."""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import trimesh

from dlovr.cache import cache_dir, slow_step

if TYPE_CHECKING:
    from dlovr.scene import SceneObject


def _self_intersects(mesh: trimesh.Trimesh) -> bool:
    """True when an edge of the mesh crosses the interior of a triangle it does not touch."""
    v = mesh.vertices
    f = mesh.faces
    edges = mesh.edges_unique
    a, b = v[edges[:, 0]], v[edges[:, 1]]
    t0, t1, t2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    scale = float(np.ptp(v, axis=0).max()) or 1.0
    eps = 1e-9
    chunk = max(1, 200_000 // max(1, len(f)))
    for s in range(0, len(edges), chunk):
        ea, eb, ei = a[s : s + chunk], b[s : s + chunk], edges[s : s + chunk]
        d = eb - ea  # (e,3)
        e1, e2 = t1 - t0, t2 - t0  # (t,3)
        h = np.cross(d[:, None, :], e2[None])  # (e,t,3)
        det = np.einsum("etk,tk->et", h, e1)
        ok = np.abs(det) > 1e-14 * scale**3
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        sv = ea[:, None, :] - t0[None]
        uu = np.einsum("etk,etk->et", sv, h) * inv
        qv = np.cross(sv, e1[None])
        vv = np.einsum("etk,ek->et", qv, d) * inv
        tt = np.einsum("etk,tk->et", qv, e2) * inv
        hit = ok & (uu >= -eps) & (vv >= -eps) & (uu + vv <= 1 + eps) & (tt > eps) & (tt < 1 - eps)
        if hit.any():
            shares = (ei[:, None, 0, None] == f[None]).any(-1) | (ei[:, None, 1, None] == f[None]).any(-1)
            if (hit & ~shares).any():
                return True
    return False


#: Meshes of more triangles than this remember that they passed the self-intersection test (its cost
#: grows with the square of the triangles: 5 s CPU for 5,120), in the cache directory by content.
CHECK_CACHE_TRIANGLES = 500
CHECK_VERSION = "self-intersection-v1"  # bump whenever _self_intersects may answer otherwise
#: Meshes of more triangles than this say what is done while they are prepared (seconds to minutes
#: for their first load: :func:`dlovr.cache.slow_step`).
SLOW_TRIANGLES = 2000


def _checked_marker(mesh: trimesh.Trimesh) -> Path:
    """The cache file that says this mesh (vertices and triangles, exactly) is not self-intersecting."""
    h = hashlib.sha256(CHECK_VERSION.encode())
    h.update(np.ascontiguousarray(mesh.vertices, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype="<i8").tobytes())
    return cache_dir() / f"meshcheck-{h.hexdigest()}.ok"


def _not_self_intersecting(mesh: trimesh.Trimesh, use_cache: bool) -> bool:
    """:func:`_self_intersects` is False; a large mesh's pass is remembered (never a failure)."""
    if not use_cache or len(mesh.faces) <= CHECK_CACHE_TRIANGLES:
        return not _self_intersects(mesh)
    marker = _checked_marker(mesh)
    if marker.is_file():
        return True
    what = f"self-intersection test of a mesh of {len(mesh.faces):,} triangles (once: then cached)"
    with slow_step(what) if len(mesh.faces) > SLOW_TRIANGLES else contextlib.nullcontext():
        if _self_intersects(mesh):
            return False
    with contextlib.suppress(OSError):  # no cache: checked again next time
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.touch()
    return True


def check_mesh(mesh: trimesh.Trimesh, *, use_cache: bool = True) -> str | None:
    """Why a mesh cannot be an environment object (None when it is fine). The self-intersection test
    of a large mesh that passed it is remembered in the cache directory (``use_cache``)."""
    if len(mesh.faces) == 0:
        return "mesh has no triangles"
    if not mesh.is_watertight:
        return "mesh is not watertight (it has open or non-manifold edges)"
    if not mesh.is_winding_consistent:
        return "mesh triangles are not consistently oriented"
    if mesh.volume <= 0:
        return "mesh is inside out or has no volume"
    if not _not_self_intersecting(mesh, use_cache):
        return "mesh is self-intersecting"
    return None


def to_manifold(mesh: trimesh.Trimesh):
    import manifold3d

    m = manifold3d.Manifold(
        manifold3d.Mesh64(
            vert_properties=np.ascontiguousarray(mesh.vertices, dtype=np.float64),
            tri_verts=np.ascontiguousarray(mesh.faces, dtype=np.uint64),
        )
    )
    return m


def _to_trimesh(m) -> trimesh.Trimesh:
    mm = m.to_mesh64()
    return trimesh.Trimesh(np.asarray(mm.vert_properties)[:, :3], np.asarray(mm.tri_verts), process=True)


def prism_mesh(profile_xz: Sequence[Sequence[float]], depth: float) -> trimesh.Trimesh:
    """A prism: the (x, z) polygon ``profile_xz`` (counter-clockwise) extruded along y, centred on y = 0."""
    import manifold3d

    prof = np.asarray(profile_xz, dtype=float)
    n = len(prof)
    caps = np.asarray(manifold3d.triangulate([prof]), dtype=np.int64).reshape(-1, 3)
    v = np.vstack(
        [
            np.column_stack([prof[:, 0], np.full(n, -depth / 2), prof[:, 1]]),
            np.column_stack([prof[:, 0], np.full(n, depth / 2), prof[:, 1]]),
        ]
    )
    tris = [caps[:, [0, 1, 2]], caps[:, [0, 2, 1]] + n]
    for i in range(n):
        j = (i + 1) % n
        tris.append(np.array([[i, i + n, j], [j, i + n, j + n]]))
    m = trimesh.Trimesh(v, np.vstack(tris), process=True)
    if m.volume < 0:
        m.invert()
    return m


def box_mesh(size: Sequence[float]) -> trimesh.Trimesh:
    """A box centred at the origin with full extents ``size``."""
    return trimesh.creation.box(extents=np.asarray(size, dtype=float))


class MeshError(ValueError):
    """An object's mesh cannot be used: one line naming the file, the object and the problem."""


MAX_MESH_TRIANGLES = 20_000


def object_local_mesh(obj: SceneObject) -> trimesh.Trimesh:
    """The object's mesh in its own frame (trimesh); raises MeshError for an unreadable mesh file.

    ``obj``: a :class:`dlovr.scene.SceneObject` (a box of full extents ``size``, or a mesh file
    scaled by ``scale``).
    """
    if obj.kind == "box":
        assert obj.size is not None
        return box_mesh(obj.size)
    assert obj.mesh_path is not None
    try:
        m = trimesh.load_mesh(str(obj.mesh_path), process=True, force="mesh")
    except Exception as e:
        raise MeshError(f"{obj.mesh_path}: cannot read mesh of object {obj.name!r}: {e}") from None
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise MeshError(f"{obj.mesh_path}: mesh of object {obj.name!r} has no triangles")
    if len(m.faces) > MAX_MESH_TRIANGLES:
        raise MeshError(
            f"{obj.mesh_path}: mesh of object {obj.name!r} has more than {MAX_MESH_TRIANGLES} triangles"
        )
    if obj.scale != 1.0:
        m.apply_scale(obj.scale)
    return m
