"""Convex decomposition of an object's mesh (local frame).

:func:`decompose_exact` cuts a watertight polyhedral mesh recursively along the planes of faces
adjacent to reflex edges, then merges pairs whose union is convex; :func:`decompose_approx` uses
CoACD for meshes that are not polyhedral enough (pieces marked approximate). :func:`decompose` picks
one and caches the result on disk by mesh content hash (``$DLOVR_CACHE_DIR``, else
``$XDG_CACHE_HOME/dlovr``, else ``~/.cache/dlovr``)."""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
from typing import Any

import numpy as np
import trimesh

from dlovr.cache import cache_dir, slow_step
from dlovr.geometry.faces import _clean, object_faces
from dlovr.geometry.mesh import SLOW_TRIANGLES, _to_trimesh, to_manifold

DECOMP_VERSION = "exact-v2"  # bump whenever decompose() may return other pieces for a mesh


class DecompositionError(ValueError):
    """The exact decomposition failed (the caller falls back to CoACD)."""


def _reflex_planes(tm: trimesh.Trimesh) -> list[tuple[np.ndarray, float]]:
    """Planes (normal, offset) of triangles adjacent to reflex (concave) edges, deterministic order."""
    adj = tm.face_adjacency
    if len(adj) == 0:
        return []
    n = tm.face_normals
    v = tm.vertices
    unshared = tm.face_adjacency_unshared
    # reflex: the unshared vertex of triangle j lies above the plane of triangle i
    h = np.einsum("ek,ek->e", v[unshared[:, 1]] - v[tm.faces[adj[:, 0], 0]], n[adj[:, 0]])
    scale = float(np.ptp(v, axis=0).max()) or 1.0
    reflex = h > 1e-9 * scale
    planes: dict[tuple, tuple[np.ndarray, float]] = {}
    for i, j in adj[reflex]:
        for t in (int(i), int(j)):
            nn = n[t]
            d = float(nn @ v[tm.faces[t, 0]])
            k = (*(_clean(round(x, 9)) for x in nn), _clean(round(d / scale, 9)))
            planes.setdefault(k, (nn, d))
    return [planes[k] for k in sorted(planes)]


def _solid_vertices(m) -> np.ndarray:
    """Vertices of a manifold that are corners of the solid.

    A cut along the plane of one of the solid's own faces can leave a zero-volume fold: a vertex whose
    triangles all lie in one plane, sticking out of the cap. Such vertices (and harmless ones inside a
    flat face) are dropped, so that they do not make a convex piece look non-convex.
    """
    mm = m.to_mesh64()
    v = np.asarray(mm.vert_properties)[:, :3]
    f = np.asarray(mm.tri_verts, dtype=np.int64)
    tn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    tn = tn / np.maximum(np.linalg.norm(tn, axis=1, keepdims=True), 1e-300)
    keep = np.zeros(len(v), dtype=bool)
    ref = np.full((len(v), 3), np.nan)
    for t in range(len(f)):
        for k in range(3):
            i = f[t, k]
            if np.isnan(ref[i, 0]):
                ref[i] = tn[t]
            elif abs(abs(float(ref[i] @ tn[t])) - 1.0) > 1e-9:
                keep[i] = True
    return v[keep]


def _convex_piece(m):
    """The piece as a clean convex manifold if it is convex (up to folds), else None."""
    import manifold3d

    pts = _solid_vertices(m)
    if len(pts) < 4:
        return None
    h = manifold3d.Manifold.hull_points(pts)
    v = m.volume()
    if abs(h.volume() - v) <= 1e-9 * max(h.volume(), 1e-300):
        return h
    return None


def _split_rec(m, depth: int, budget: list[int]) -> list:
    """Convex pieces of ``m`` by recursive cuts along reflex-face planes (backtracking on failure)."""
    if m.is_empty() or m.volume() <= 0:
        return []
    cp = _convex_piece(m)
    if cp is not None:
        return [cp]
    budget[0] -= 1
    if depth > 40 or budget[0] < 0:
        raise DecompositionError("too many cuts")
    tm = _to_trimesh(m)
    vol = m.volume()
    cands = []
    for k, (nn, d) in enumerate(_reflex_planes(tm)):
        a, b = m.split_by_plane(nn, d)
        va, vb = a.volume(), b.volume()
        if va <= 1e-9 * vol or vb <= 1e-9 * vol:
            continue
        parts = [p for side in (a, b) for p in side.decompose()]
        # prefer cuts that leave the fewest non-convex parts, then the most balanced
        score = (sum(_convex_piece(p) is None for p in parts), len(parts), abs(va - vb), k)
        cands.append((score, parts))
    cands.sort(key=lambda c: c[0])
    for _, parts in cands:
        try:
            return [q for p in parts for q in _split_rec(p, depth + 1, budget)]
        except DecompositionError:
            if budget[0] < 0:
                raise
    raise DecompositionError("no reflex-edge plane splits a non-convex piece")


def _merge_convex(pieces: list) -> list:
    """Merge pairs of pieces whose union is convex, until none is left (greedy, deterministic)."""
    pieces = list(pieces)
    changed = True
    while changed:
        changed = False
        for i in range(len(pieces)):
            for j in range(i + 1, len(pieces)):
                u = pieces[i] + pieces[j]
                cu = _convex_piece(u) if len(u.decompose()) == 1 else None
                if cu is not None:
                    pieces[i] = cu
                    del pieces[j]
                    changed = True
                    break
            if changed:
                break
    return pieces


def decompose_exact(mesh: trimesh.Trimesh) -> list[np.ndarray]:
    """Exact convex decomposition of a watertight polyhedral mesh: vertex arrays of the pieces."""
    m = to_manifold(mesh)
    if m.is_empty():
        raise DecompositionError(f"mesh is not a manifold solid ({m.status()})")
    pieces = _merge_convex(_split_rec(m, 0, [500]))
    total = sum(p.volume() for p in pieces)
    if abs(total - m.volume()) > 1e-8 * m.volume():
        raise DecompositionError("pieces do not add up to the object's volume")
    out = [np.asarray(p.to_mesh64().vert_properties)[:, :3].copy() for p in pieces]
    out.sort(key=lambda v: tuple(np.round(v.mean(axis=0), 9)))
    return out


def decompose_approx(mesh: trimesh.Trimesh) -> list[np.ndarray]:
    """Approximate convex decomposition with CoACD (fixed seed, deterministic)."""
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int32)),
        threshold=0.05,
        preprocess_mode="off",
        seed=0,
    )
    out = [np.asarray(v, dtype=float) for v, _ in parts]
    out.sort(key=lambda v: tuple(np.round(v.mean(axis=0), 9)))
    return out


def mesh_hash(mesh: trimesh.Trimesh) -> str:
    h = hashlib.sha256(DECOMP_VERSION.encode())
    h.update(np.ascontiguousarray(mesh.vertices, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype="<i8").tobytes())
    return h.hexdigest()


MAX_EXACT_FACES = 400  # more object faces than this: not polyhedral enough, use CoACD


def _decompose(mesh: trimesh.Trimesh) -> tuple[list[np.ndarray], bool]:
    """The exact decomposition, else CoACD's (approximate)."""
    try:
        if len(object_faces(mesh)) > MAX_EXACT_FACES:
            raise DecompositionError("too many faces for an exact decomposition")
        return decompose_exact(mesh), False
    except DecompositionError:
        return decompose_approx(mesh), True


def decompose(mesh: trimesh.Trimesh, *, use_cache: bool = True) -> tuple[list[np.ndarray], bool]:
    """Convex pieces (vertex arrays, local frame) and whether they are approximate. Cached on disk."""
    key = mesh_hash(mesh)
    path = cache_dir() / f"decomp-{key}.npz"
    if use_cache and path.is_file():
        try:
            with np.load(path) as z:
                n = int(z["n"])
                return [z[f"p{i}"] for i in range(n)], bool(z["approximate"])
        except Exception:
            pass
    what = f"convex decomposition of a mesh of {len(mesh.faces):,} triangles (once: then cached)"
    with slow_step(what) if len(mesh.faces) > SLOW_TRIANGLES else contextlib.nullcontext():
        pieces, approximate = _decompose(mesh)
    if use_cache:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            buf = io.BytesIO()
            arrays: dict[str, Any] = {f"p{i}": p for i, p in enumerate(pieces)}
            np.savez(buf, n=len(pieces), approximate=approximate, **arrays)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(buf.getvalue())
            os.replace(tmp, path)
        except OSError:
            pass
    return pieces, approximate
