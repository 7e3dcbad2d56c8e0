"""Polyhedral environment geometry (MODEL.md §1, §3.3; issue 3).

Pure: numpy, scipy, trimesh, manifold3d and (as a fallback) coacd. No simulator, no UI.

- :func:`object_faces`: an object's faces, i.e. coplanar edge-connected triangle groups, numbered
  ``F1…Fk`` deterministically from the object's own surface in its local frame (pose-independent).
- :func:`decompose`: exact convex decomposition of a watertight polyhedral mesh (recursive planar cuts
  along the planes of faces adjacent to reflex edges, then merging of pairs whose union is convex);
  CoACD for meshes that are not polyhedral enough (pieces marked approximate). Cached on disk by mesh
  content hash (``$DLOVR_CACHE_DIR``, else ``$XDG_CACHE_HOME/dlovr``, else ``~/.cache/dlovr``).
- :class:`SceneGeometry`: world-frame convex pieces with labelled faces (external / internal / mixed,
  mapped to object face names), the per-object edge table, classification of cable points into
  environment primitives (closest point, distance, active faces by a *tangential* tolerance), and the
  :class:`~dlovr.model.discrete.FactBook` (face normals, concave/convex and opening angles of face pairs).

Typical use by the simulation::

    geom = SceneGeometry.from_scene(scene)
    sit = geom.situation(points)                 # topology.Situation (V_S gripped, end-vertex rule)
    disc = geom.discrete_situation(points)       # discrete.DiscreteSituation
"""

from __future__ import annotations

import hashlib
import io
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
import trimesh

from dlovr.model.discrete import (
    ContactFacts,
    DiscreteSituation,
    FaceFact,
    FactBook,
    ModelParams,
    PairFact,
    discretize,
)
from dlovr.model.topology import Contact, EnvPrimitive, Situation, situation_from_points
from dlovr.transforms import pose_matrix

if TYPE_CHECKING:
    from dlovr.scene import Scene

DECOMP_VERSION = "exact-v2"  # bump whenever decompose() may return other pieces for a mesh
_ANGLE_TOL = 1e-5  # rad: triangles whose normals differ less are coplanar (one face)


# --------------------------------------------------------------------------------------------------
# Small vector helpers
# --------------------------------------------------------------------------------------------------


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n == 0.0, 1.0, n)


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
    n = _unit(np.cross(b - a, c - a))  # (t,3)
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


def _closest_on_segments(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points on segments (E) to points p (m,3): returns (q (m,E,3), dist (m,E))."""
    ab = b - a
    den = np.einsum("ek,ek->e", ab, ab)
    den = np.where(den == 0.0, 1.0, den)
    t = np.einsum("mek,ek->me", p[:, None, :] - a[None], ab) / den
    t = np.clip(t, 0.0, 1.0)
    q = a[None] + t[..., None] * ab[None]
    return q, np.linalg.norm(p[:, None, :] - q, axis=2)


# --------------------------------------------------------------------------------------------------
# Object faces
# --------------------------------------------------------------------------------------------------


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
        n = _unit((mesh.face_normals[tris] * w[:, None]).sum(axis=0))
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


# --------------------------------------------------------------------------------------------------
# Mesh validation helpers
# --------------------------------------------------------------------------------------------------


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


def check_mesh(mesh: trimesh.Trimesh) -> str | None:
    """Why a mesh cannot be an environment object (None when it is fine)."""
    if len(mesh.faces) == 0:
        return "mesh has no triangles"
    if not mesh.is_watertight:
        return "mesh is not watertight (it has open or non-manifold edges)"
    if not mesh.is_winding_consistent:
        return "mesh triangles are not consistently oriented"
    if mesh.volume <= 0:
        return "mesh is inside out or has no volume"
    if _self_intersects(mesh):
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


# --------------------------------------------------------------------------------------------------
# Convex decomposition
# --------------------------------------------------------------------------------------------------


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
        coacd.Mesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)),
        threshold=0.05,
        preprocess_mode="off",
        seed=0,
    )
    out = [np.asarray(v, dtype=float) for v, _ in parts]
    out.sort(key=lambda v: tuple(np.round(v.mean(axis=0), 9)))
    return out


def cache_dir() -> Path:
    env = os.environ.get("DLOVR_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "dlovr"


def mesh_hash(mesh: trimesh.Trimesh) -> str:
    h = hashlib.sha256(DECOMP_VERSION.encode())
    h.update(np.ascontiguousarray(mesh.vertices, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype="<i8").tobytes())
    return h.hexdigest()


MAX_EXACT_FACES = 400  # more object faces than this: not polyhedral enough, use CoACD


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
    approximate = False
    try:
        if len(object_faces(mesh)) > MAX_EXACT_FACES:
            raise DecompositionError("too many faces for an exact decomposition")
        pieces = decompose_exact(mesh)
    except DecompositionError:
        pieces, approximate = decompose_approx(mesh), True
    if use_cache:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            buf = io.BytesIO()
            np.savez(
                buf, n=len(pieces), approximate=approximate, **{f"p{i}": p for i, p in enumerate(pieces)}
            )
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(buf.getvalue())
            os.replace(tmp, path)
        except OSError:
            pass
    return pieces, approximate


def scene_pieces(scene: Scene, *, use_cache: bool = True) -> dict[str, tuple[list[np.ndarray], bool]]:
    """The convex decomposition of every object of a scene: name -> (pieces in the local frame,
    approximate?). The simulator and the geometry must use the same one (piece k is MuJoCo's geom
    ``<obj>.P<k>``), and a recording keeps it so that replay does not depend on the algorithm."""
    from dlovr.scene import object_local_mesh

    return {o.name: decompose(object_local_mesh(o), use_cache=use_cache) for o in scene.objects}


# --------------------------------------------------------------------------------------------------
# Convex pieces
# --------------------------------------------------------------------------------------------------

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
    for eq in hull.equations:
        n, d = eq[:3], -eq[3]
        nn = float(np.linalg.norm(n))
        n, d = n / nn, d / nn
        for k, m in enumerate(normals):
            if float(n @ m) > 1 - 1e-12 and abs(d - offsets[k]) < 1e-9 * scale:
                break
        else:
            normals.append(n)
            offsets.append(d)
    polys = []
    for n, d in zip(normals, offsets, strict=True):
        on = pts[np.abs(pts @ n - d) < 1e-9 * scale]
        c = on.mean(axis=0)
        u = _unit(on[0] - c) if np.linalg.norm(on[0] - c) > 0 else _unit(np.cross(n, [1.0, 0, 0]))
        w = np.cross(n, u)
        ang = np.arctan2((on - c) @ w, (on - c) @ u)
        polys.append(on[np.argsort(ang)])
    return np.array(normals), np.array(offsets), polys, pts


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
    for n, d, poly in zip(normals, offsets, polys, strict=True):
        area = _polygon_area(poly)
        best_name, best_overlap, best_tris = None, 0.0, np.zeros((0, 3, 3))
        for name, on, od, tris in obj_faces:
            if float(n @ on) < 1 - 1e-9 or abs(d - od) > 1e-7 * scale:
                continue
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
    # edges: pairs of faces sharing two hull vertices
    ea, eb, ef = [], [], []
    on_face = [np.abs(pts @ n - d) < 1e-9 * scale for n, d in zip(normals, offsets, strict=True)]
    for i in range(len(faces)):
        for j in range(i + 1, len(faces)):
            shared = pts[on_face[i] & on_face[j]]
            if len(shared) < 2:
                continue
            e = _unit(np.cross(normals[i], normals[j]))
            s = shared @ e
            ea.append(shared[int(np.argmin(s))])
            eb.append(shared[int(np.argmax(s))])
            ef.append((i, j))
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


# --------------------------------------------------------------------------------------------------
# Objects and the edge table
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LabelBudgets:
    """How far the point of each queried (point, piece) pair may move, split by direction, before
    what :meth:`SceneGeometry.pair_hits` reports for the pair could change: the
    :meth:`SceneGeometry.label_slack` of each pair, split by direction
    (:meth:`SceneGeometry.pair_hits_and_slack` gives them). Rows are the pairs as queried.
    ``normal``: (K,3) unit normal (world frame) of the pair's nearest face plane; ``along`` (m):
    budget for the move's component along it; ``across`` (m): for its component in that plane;
    ``any`` (m): for the whole move. A move keeps the labels when it is under all three
    (:meth:`keeps`).

    A point over the inside of a face keeps its labels however far it moves across the face (a
    cable sliding on it, or a segment's contact point jumping along it) until it nears the face's
    edges, outline or cover: the decisions about the face plane's residual depend on the move along
    the normal alone, those about the projection onto it on the move across it alone, and which
    plane is nearest stays put while the whole move is under half the gap to the next. Points near
    an edge or vertex, and pairs beyond reach, get their slack in every direction."""

    normal: np.ndarray
    along: np.ndarray
    across: np.ndarray
    any: np.ndarray

    def keeps(self, rows: np.ndarray, moves: np.ndarray) -> np.ndarray:
        """Whether moving the points of pairs ``rows`` by ``moves`` ((m,3), m) keeps their labels."""
        d2 = np.einsum("ij,ij->i", moves, moves)
        dn = np.einsum("ij,ij->i", moves, self.normal[rows])
        dn2 = dn * dn
        return (
            (d2 < self.any[rows] ** 2) & (dn2 < self.along[rows] ** 2) & (d2 - dn2 < self.across[rows] ** 2)
        )


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
    pieces = [
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
        pieces,
        edges,
        approximate,
    )


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


# --------------------------------------------------------------------------------------------------
# Point classification
# --------------------------------------------------------------------------------------------------


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


class SceneFactBook(FactBook):
    """FactBook of a scene: every object face, and pair facts computed on demand from the geometry."""

    def __init__(self, geom: SceneGeometry):
        faces = {
            n: FaceFact(n, o.name, tuple(float(x) for x in o.face_normals[k]))  # type: ignore[arg-type]
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

    def for_contact(self, contact: Contact, dlo_vector=None) -> ContactFacts:  # type: ignore[override]
        names = [f for f in contact.faces if f in self.faces]
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                self.pair(a, b)
        return super().for_contact(contact, dlo_vector)


class SceneGeometry:
    """World-frame geometry of a scene's objects (see module docstring)."""

    def __init__(
        self, objects: Iterable[GeomObject], radius: float = 0.005, params: ModelParams | None = None
    ):
        self.objects = list(objects)
        self.radius = float(radius)
        self.params = params or ModelParams()
        self.pieces = [p for o in self.objects for p in o.pieces]
        self._by_name = {o.name: o for o in self.objects}
        self._face_owner = {n: (o, k) for o in self.objects for k, n in enumerate(o.face_names)}
        self._book: SceneFactBook | None = None
        self._piece_ids: dict[tuple[str, int], int] | None = None
        self._pad: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._outlines: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._box: tuple[np.ndarray, np.ndarray] | None = None

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_scene(
        cls,
        scene: Scene,
        *,
        use_cache: bool = True,
        pieces: dict[str, tuple[list[np.ndarray], bool]] | None = None,
    ) -> SceneGeometry:
        """Geometry of a scene; ``pieces`` (see :func:`scene_pieces`) fixes the decomposition."""
        from dlovr.scene import object_local_mesh

        objs = [
            build_object(
                o.name, object_local_mesh(o), pose_matrix(o.pos, o.quat), use_cache=use_cache,
                pieces=None if pieces is None else pieces[o.name],
            )
            for o in scene.objects
        ]  # fmt: skip
        return cls(objs, scene.dlo.radius, scene.params)

    @classmethod
    def from_meshes(
        cls,
        meshes: dict[str, trimesh.Trimesh | tuple[trimesh.Trimesh, np.ndarray]],
        radius: float = 0.005,
        params: ModelParams | None = None,
        *,
        use_cache: bool = True,
    ) -> SceneGeometry:
        """From ``{name: mesh}`` or ``{name: (local mesh, 4x4 pose)}`` (tests, tools)."""
        objs = []
        for name, m in meshes.items():
            mesh, pose = m if isinstance(m, tuple) else (m, None)
            objs.append(build_object(name, mesh, pose, use_cache=use_cache))
        return cls(objs, radius, params)

    def object(self, name: str) -> GeomObject:
        return self._by_name[name]

    def face_normal(self, face: str) -> np.ndarray:
        o, k = self._face_owner[face]
        return o.face_normals[k]

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

    def _best_planes(
        self, pts: np.ndarray, pi: np.ndarray, pc: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For (point, piece) pairs: the points (K,3), their plane residuals (K,F), the plane of the
        largest residual (its index, residual and normal) and the residuals of the projection onto it
        against the piece's other planes (K,F; -inf for the plane itself)."""
        n_all, d_all, _, _, _ = self._padded()
        p = pts[pi]
        nrm, off = n_all[pc], d_all[pc]  # (K,F,3), (K,F)
        res = np.einsum("kfi,ki->kf", nrm, p) - off
        k = np.arange(len(pi))
        best = np.argmax(res, axis=1)
        rb = res[k, best]
        nb = nrm[k, best]
        resq = res - rb[:, None] * np.einsum("kfi,ki->kf", nrm, nb)  # residuals of the projection
        resq[k, best] = -np.inf
        return p, res, best, rb, nb, resq

    def pair_hits(
        self,
        points: np.ndarray,
        point_idx: np.ndarray,
        piece_idx: np.ndarray,
        contact_tol: float = 5e-4,
        tangential_tol: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[str, ...]], np.ndarray]:
        """Contacts of given (point, piece id) pairs as arrays, sorted by point then piece:
        point indices, piece ids (into :attr:`pieces`), distances (m), face names, closest points.

        A pair whose closest point lies inside one face, at least the tangential tolerance away from
        that face's other planes (the distance from the projection to any edge of the face is at
        least its distance to the other face's plane), is decided here in one numpy pass: a contact
        with that face when it is exposed there (external, or the exposed part of a mixed face, and
        not covered by another object), else no contact with that piece. Points with any other pair
        (near an edge or a vertex) go through :meth:`classify_points`.
        """
        return self._pair_hits(points, point_idx, piece_idx, contact_tol, tangential_tol, None)[:5]

    def label_slack(
        self,
        points: np.ndarray,
        point_idx: np.ndarray,
        piece_idx: np.ndarray,
        contact_tol: float = 5e-4,
        tangential_tol: float | None = None,
        thresholds: Sequence[float] = (),
    ) -> np.ndarray:
        """How far (m) each point may move without changing what :meth:`pair_hits` reports for the
        same (point, piece) pairs: which pairs touch, with which faces, and on which side of every
        distance in ``thresholds`` each touching pair lies. (n,) array over ``points``; ``inf`` for
        points not queried, 0 where no bound is known (a point inside a piece).

        Every decision of :meth:`pair_hits` and :meth:`classify_points` compares a 1-Lipschitz
        function of the point with a constant: plane residuals and their maximum, the distance to a
        convex piece, the closest point on it (a projection, non-expansive) and so its distances to
        the piece's edges, the outline of a mixed face's exposed part and the free-side probes of
        its faces. The slack is the smallest of those margins (the best-plane choice, a difference
        of two residuals, counts half). A point that moves by less than its slack gets the same
        labels, so a caller may reuse them. :meth:`pair_hits_and_slack` gives both in one pass.
        """
        return self.pair_hits_and_slack(
            points, point_idx, piece_idx, contact_tol, tangential_tol, thresholds
        )[5]

    def pair_hits_and_slack(
        self,
        points: np.ndarray,
        point_idx: np.ndarray,
        piece_idx: np.ndarray,
        contact_tol: float = 5e-4,
        tangential_tol: float | None = None,
        thresholds: Sequence[float] = (),
    ) -> tuple[
        np.ndarray, np.ndarray, np.ndarray, list[tuple[str, ...]], np.ndarray, np.ndarray, LabelBudgets
    ]:
        """:meth:`pair_hits`, :meth:`label_slack` and the same slack per pair split by direction
        (:class:`LabelBudgets`), computed together."""
        out = self._pair_hits(points, point_idx, piece_idx, contact_tol, tangential_tol, tuple(thresholds))
        return out  # type: ignore[return-value]

    def _pair_hits(
        self,
        points: np.ndarray,
        point_idx: np.ndarray,
        piece_idx: np.ndarray,
        contact_tol: float,
        tangential_tol: float | None,
        thresholds: tuple[float, ...] | None,
    ) -> tuple[
        np.ndarray,
        np.ndarray,
        np.ndarray,
        list[tuple[str, ...]],
        np.ndarray,
        np.ndarray | None,
        LabelBudgets | None,
    ]:
        """:meth:`pair_hits`, and its slack per point and budgets per pair when ``thresholds`` is not
        ``None``."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        pi, pc = np.asarray(point_idx, dtype=np.int64), np.asarray(piece_idx, dtype=np.int64)
        r = self.radius
        ttol = r / 5.0 if tangential_tol is None else float(tangential_tol)
        reach = r + contact_tol
        slack = None if thresholds is None else np.full(len(pts), np.inf)
        if len(pi) == 0:
            none = None if slack is None else LabelBudgets(np.zeros((0, 3)), *(np.zeros(0) for _ in range(3)))
            return (
                np.zeros(0, np.int64),
                np.zeros(0, np.int64),
                np.zeros(0),
                [],
                np.zeros((0, 3)),
                slack,
                none,
            )
        _, _, names, external, owner = self._padded()
        p, res, best, rb, nb, resq = self._best_planes(pts, pi, pc)
        q = p - rb[:, None] * nb  # the closest point when it lies inside the face
        rq = resq.max(axis=1)
        # the distance to a convex piece is at least its largest plane residual: beyond reach, no hit
        far = rb > reach
        interior = (rq <= -ttol) & ~far  # inside one face, away from all its edges
        ext = external[pc, best]
        exposed = interior & ext
        mixed = np.zeros(len(pi), dtype=bool)
        for j in np.nonzero(interior & ~ext)[0]:
            pf = self.pieces[int(pc[j])].faces[int(best[j])]  # a mixed face: is q on its exposed part?
            mixed[j] = pf.label == "mixed"
            exposed[j] = mixed[j] and bool(_points_in_triangles(q[j : j + 1], pf.exposed, 1e-9)[0])
        # a face covered by another object there (a box's bottom on the table) is no contact face:
        # probe the free side as classify_points does
        probed = interior & (ext | mixed) if slack is not None else exposed
        cover_res = None
        probe_rows = np.nonzero(probed)[0]
        if len(probe_rows):
            cover_res = self._probe_residuals(q[probe_rows] + 2.0 * r * nb[probe_rows], owner[pc[probe_rows]])
            covered = np.zeros(len(pi), dtype=bool)
            covered[probe_rows] = (cover_res < -1e-9).any(axis=1)
            exposed &= ~covered
        decided = far | interior  # interior but not exposed: the piece has no contact face here
        amb_points = np.unique(pi[~decided])
        take = exposed & (rb <= reach) & ~np.isin(pi, amb_points)
        pt, pid, dist = pi[take], pc[take], rb[take]
        faces = [(f,) for f in names[pid, best[take]].tolist()]
        closest = q[take]
        budgets = None
        if slack is not None:
            # margins by what they depend on: the best plane's residual moves with the move along its
            # normal, the projection q (and its edges, outline and probes) with the move across it
            second = np.partition(res, -2, axis=1)[:, -2] if res.shape[1] > 1 else np.full(len(pi), -np.inf)
            along = np.where(far, np.inf, np.abs(rb - reach))
            across = np.where(far, np.inf, np.abs(rq + ttol))
            whole = np.where(far, rb - reach, (rb - second) / 2.0)
            for j in np.nonzero(interior & mixed)[0]:
                pf = self.pieces[int(pc[j])].faces[int(best[j])]
                across[j] = min(across[j], self._outline_slack(pf, q[j : j + 1])[0])
            if cover_res is not None:
                rows = probe_rows
                m = np.abs(cover_res + 1e-9).min(axis=1) if cover_res.shape[1] else np.full(len(rows), np.inf)
                across[rows] = np.minimum(across[rows], m)
                for t in thresholds or ():
                    along[rows] = np.minimum(along[rows], np.abs(rb[rows] - t))
            margin = np.minimum(np.minimum(along, across), whole)
            np.minimum.at(slack, pi, margin)
            budgets = (along, across, whole)
        if len(amb_points):
            extra, amb_slack = self._classify(pts[amb_points], r, contact_tol, ttol, thresholds)
            pt = np.concatenate([pt, amb_points[[h.point for h in extra]].astype(np.int64)])
            pid = np.concatenate(
                [pid, np.array([self.piece_id(h.piece.obj, h.piece.index) for h in extra], np.int64)]
            )
            dist = np.concatenate([dist, [h.distance for h in extra]])
            faces = faces + [h.faces for h in extra]
            closest = np.concatenate([closest, np.array([h.closest for h in extra]).reshape(-1, 3)])
            if slack is not None and amb_slack is not None:
                slack[amb_points] = np.minimum(slack[amb_points], amb_slack)
        pair_budgets = None
        if budgets is not None:  # given with the slack
            along, across, whole = budgets
            if len(amb_points):  # near an edge or vertex: the point's slack, in every direction
                amb = np.isin(pi, amb_points)
                along[amb], across[amb], whole[amb] = np.inf, np.inf, slack[pi[amb]]
            pair_budgets = LabelBudgets(nb, along, across, whole)
        order = np.lexsort((pid, pt))
        faces = [faces[i] for i in order.tolist()]
        return pt[order], pid[order], dist[order], faces, closest[order], slack, pair_budgets

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

    def situation(
        self,
        points: np.ndarray,
        *,
        gripped: bool = True,
        gripper_z: Sequence[float] | None = None,
        radius: float | None = None,
        contact_tol: float = 5e-4,
        tangential_tol: float | None = None,
    ) -> Situation:
        """Topological situation of a cable polyline (point 0 = V_S, last = V_E).

        ``V_S`` touches the gripper when ``gripped``; the end-vertex rule (MODEL.md §2) is applied by
        :func:`dlovr.model.topology.situation_from_points`.
        """
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(pts) < 2:
            raise ValueError("a cable polyline needs at least two points")
        z = tuple(float(x) for x in (gripper_z if gripper_z is not None else (0.0, 0.0, 1.0)))
        return situation_from_points(
            self.point_primitives(pts, radius, contact_tol, tangential_tol),
            np.diff(pts, axis=0),
            self.face_normal,
            tip_angle_deg=self.params.tip_angle_deg,
            gripped=gripped,
            gripper_z=z,  # type: ignore[arg-type]
        )

    def discrete_situation(self, points: np.ndarray, **kw) -> DiscreteSituation:
        """Discrete situation of a cable polyline: :meth:`situation` then the model (MODEL.md §3.3)."""
        return discretize(self.situation(points, **kw), self.fact_book(), self.params)

    # ---------------------------------------------------------------- facts
    def fact_book(self) -> SceneFactBook:
        """FaceFact for every object face; PairFacts computed (and cached) on demand."""
        if self._book is None:
            self._book = SceneFactBook(self)
        return self._book

    def pair_fact(self, a: str, b: str) -> PairFact:
        """Concave/convex and free-space opening angle of two faces (any objects), NOTES.md method.

        From the closest points of the two faces, probe in-plane toward the other face's outward side
        (a distance of the DLO radius): the pair is concave iff both faces continue there, exposed.
        """
        oa, ka = self._face_owner[a]
        ob, kb = self._face_owner[b]
        na, nb = oa.face_normals[ka], ob.face_normals[kb]
        cosang = float(np.clip(na @ nb, -1.0, 1.0))
        alpha = float(np.degrees(np.arccos(cosang)))
        cross = np.cross(na, nb)
        crease = tuple(float(x) for x in _unit(cross)) if np.linalg.norm(cross) > 1e-9 else None
        if np.linalg.norm(cross) <= 1e-12:
            # parallel (same side: one plane; opposite: facing walls, a slot): treat as concave
            return PairFact(a, b, True, 180.0 - alpha, None)
        ta, tb = oa.face_tris[ka], ob.face_tris[kb]
        pa, pb = _closest_between_triangle_sets(ta, tb)
        ua = _unit(nb - cosang * na)
        ub = _unit(na - cosang * nb)
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
        return PairFact(a, b, concave, opening, crease)  # type: ignore[arg-type]

    # ---------------------------------------------------------------- description
    def describe(self) -> dict:
        """JSON-able description: objects, pieces (exact or approximate), faces, edge table."""
        out = []
        for o in self.objects:
            out.append(
                {
                    "name": o.name,
                    "approximate": o.approximate,
                    "faces": [
                        {
                            "name": n,
                            "normal": [round(float(x), 6) + 0.0 for x in o.face_normals[k]],
                            "area": round(float(o.face_areas[k]), 9),
                        }
                        for k, n in enumerate(o.face_names)
                    ],
                    "pieces": [
                        {
                            "index": p.index,
                            "kind": "approximate" if p.approximate else "exact",
                            "volume": round(p.volume, 12),
                            "faces": [
                                {
                                    "face": f.face,
                                    "kind": f.label,
                                    "normal": [round(float(x), 6) + 0.0 for x in f.normal],
                                }
                                for f in p.faces
                            ],
                        }
                        for p in o.pieces
                    ],
                    "edges": [
                        {
                            "faces": [e.a, e.b],
                            "kind": "convex" if e.convex else "concave",
                            "opening_deg": round(e.opening_deg, 6),
                            "length": round(e.length, 9),
                        }
                        for e in o.edges
                    ],
                }
            )
        return {"objects": out}


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
    c = _unit(crease)
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
        n = _unit(np.cross(b - a, c - a))
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


__all__ = [
    "EdgeInfo",
    "GeomObject",
    "ObjectFace",
    "Piece",
    "PieceFace",
    "PointHit",
    "SceneFactBook",
    "SceneGeometry",
    "box_mesh",
    "build_object",
    "cache_dir",
    "check_mesh",
    "decompose",
    "decompose_exact",
    "object_faces",

    "prism_mesh",

]
