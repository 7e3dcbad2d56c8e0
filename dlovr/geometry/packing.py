"""The scene's convex pieces packed once into two flat arrays for the compiled labelling kernels
(:mod:`dlovr.geometry.kernels`): one of floats (world frame, metres), one of integers, each a
sequence of sections whose counts and offsets head the integer array (layout below)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dlovr.geometry.pieces import Piece
from dlovr.geometry.vectors import _tri_frames

# header of the integer array: counts, then the offsets of the float and the integer sections
P_, F_, E_, T_, O_ = 0, 1, 2, 3, 4
HEAD = 8
FLOAT_SECTIONS = ("normals", "offsets", "lo", "hi", "eps", "edge_a", "edge_b", "tri_start", "tri_in",
                  "outline_a", "outline_b")
INT_SECTIONS = ("nfaces", "label", "name", "owner", "edge_range", "edge_faces", "tri_range", "outline_range")

EXTERNAL, INTERNAL, MIXED = 1, 0, 2  # piece face labels (an internal face has no object face)


@dataclass(frozen=True, eq=False)
class PackedPieces:
    """Convex pieces as the kernels read them.

    ``floats``/``ints``: the packed arrays; ``face_names``: object face names by face id (ids sorted
    by name, so that sorting ids sorts names); ``width``: the most faces of one piece (the width of
    a hit's face row).

    Per piece ``k`` and face ``f`` (padded to the most faces of a piece): unit outward ``normals``
    (P,F,3) and ``offsets`` (P,F) (a padded face: zero normal, offset 1e9), ``label`` (external 1,
    internal 0, mixed 2), ``name`` (face id, -1 for internal faces); per piece its box ``lo``/``hi``,
    tolerance ``eps`` (1e-9 of its size, at least 1e-12 m), object index ``owner``, and ranges into
    its edges (``edge_a``/``edge_b`` end points, ``edge_faces`` the two faces of each), and, per face
    (index ``k * F + f``), into the exposed triangles of mixed faces (edge start points and inward
    in-plane edge normals, (3,3) each) and the outline segments of their exposed part.
    """

    floats: np.ndarray
    ints: np.ndarray
    face_names: tuple[str, ...]
    width: int


def pack_pieces(pieces: Sequence[Piece], object_names: Sequence[str]) -> PackedPieces:
    """Pack ``pieces`` (world frame; ``object_names`` orders the objects for ``owner``)."""
    n_p = len(pieces)
    n_f = max((len(p.faces) for p in pieces), default=1)
    names = sorted({pf.face for p in pieces for pf in p.faces if pf.face is not None})
    face_id = {n: i for i, n in enumerate(names)}
    obj_index = {o: i for i, o in enumerate(object_names)}
    normals = np.zeros((n_p, n_f, 3))
    offsets = np.full((n_p, n_f), 1e9)
    label = np.zeros((n_p, n_f), np.int64)
    name = np.full((n_p, n_f), -1, np.int64)
    eps = np.zeros(n_p)
    edge_range = np.zeros(n_p + 1, np.int64)
    tri_range = np.zeros(n_p * n_f + 1, np.int64)
    outline_range = np.zeros(n_p * n_f + 1, np.int64)
    starts: list[np.ndarray] = []
    inwards: list[np.ndarray] = []
    out_a: list[np.ndarray] = []
    out_b: list[np.ndarray] = []
    for k, p in enumerate(pieces):
        eps[k] = 1e-9 * max(float(np.ptp(p.vertices, axis=0).max()), 1e-3)
        edge_range[k + 1] = edge_range[k] + len(p.edge_a)
        for f, pf in enumerate(p.faces):
            normals[k, f], offsets[k, f] = pf.normal, pf.offset
            if pf.face is not None and pf.label != "internal":
                name[k, f] = face_id[pf.face]
                label[k, f] = EXTERNAL if pf.label == "external" else MIXED
            j = k * n_f + f
            tri_range[j + 1] = tri_range[j]
            outline_range[j + 1] = outline_range[j]
            if label[k, f] == MIXED:
                tris = np.asarray(pf.exposed, dtype=float).reshape(-1, 3, 3)
                if len(tris):
                    s, w = _tri_frames(tris)
                    starts.append(s)
                    inwards.append(w)
                    tri_range[j + 1] += len(tris)
                a, b = _outline(tris)
                out_a.append(a)
                out_b.append(b)
                outline_range[j + 1] += len(a)
        for j in range(len(p.faces), n_f):  # padded faces: empty ranges
            tri_range[k * n_f + j + 1] = tri_range[k * n_f + j]
            outline_range[k * n_f + j + 1] = outline_range[k * n_f + j]
    cat3 = lambda parts, shape: np.concatenate(parts).reshape(shape) if parts else np.zeros(shape)  # noqa: E731
    floats = [
        normals,
        offsets,
        np.array([p.lo for p in pieces]).reshape(-1, 3),
        np.array([p.hi for p in pieces]).reshape(-1, 3),
        eps,
        np.concatenate([p.edge_a for p in pieces]).reshape(-1, 3) if n_p else np.zeros((0, 3)),
        np.concatenate([p.edge_b for p in pieces]).reshape(-1, 3) if n_p else np.zeros((0, 3)),
        cat3(starts, (-1, 3, 3)) if starts else np.zeros((0, 3, 3)),
        cat3(inwards, (-1, 3, 3)) if inwards else np.zeros((0, 3, 3)),
        np.concatenate(out_a).reshape(-1, 3) if out_a else np.zeros((0, 3)),
        np.concatenate(out_b).reshape(-1, 3) if out_b else np.zeros((0, 3)),
    ]
    ints = [
        np.array([len(p.faces) for p in pieces], np.int64),
        label,
        name,
        np.array([obj_index[p.obj] for p in pieces], np.int64),
        edge_range,
        np.concatenate([np.asarray(p.edge_faces, np.int64).reshape(-1, 2) for p in pieces])
        if n_p
        else np.zeros((0, 2), np.int64),
        tri_range,
        outline_range,
    ]
    counts = [n_p, n_f, int(edge_range[-1]), int(tri_range[-1]), int(outline_range[-1])]
    head = np.zeros(HEAD + len(FLOAT_SECTIONS) + len(INT_SECTIONS) + 2, np.int64)
    head[: len(counts)] = counts
    pos = 0
    for i, a in enumerate(floats):
        head[HEAD + i] = pos
        pos += a.size
    head[HEAD + len(floats)] = pos
    pos = len(head)
    for i, a in enumerate(ints):
        head[HEAD + len(floats) + 1 + i] = pos
        pos += a.size
    head[-1] = pos
    flat_f = np.concatenate([np.ascontiguousarray(a, dtype=float).ravel() for a in floats])
    flat_i = np.concatenate([head, *(np.ascontiguousarray(a, dtype=np.int64).ravel() for a in ints)])
    return PackedPieces(flat_f, flat_i, tuple(names), n_f)


def _outline(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The outline of a set of triangles: their edges not shared by two of them, as end points."""
    count: dict[tuple[tuple[float, ...], tuple[float, ...]], int] = {}
    for tri in tris:
        for i in range(3):
            a, b = tuple(tri[i].tolist()), tuple(tri[(i + 1) % 3].tolist())
            e = (a, b) if a <= b else (b, a)
            count[e] = count.get(e, 0) + 1
    outline = [e for e, c in count.items() if c == 1]
    return (
        np.array([e[0] for e in outline], dtype=float).reshape(-1, 3),
        np.array([e[1] for e in outline], dtype=float).reshape(-1, 3),
    )
