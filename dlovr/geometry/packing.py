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
    n_f = max((len(p.faces) for p in pieces), default=1)
    names = sorted({pf.face for p in pieces for pf in p.faces if pf.face is not None})
    face_id = {n: i for i, n in enumerate(names)}
    t = _face_tables(pieces, n_f, face_id)
    floats = _float_sections(pieces, t)
    ints = _int_sections(pieces, object_names, t)
    counts = [len(pieces), n_f, int(t.edge_range[-1]), int(t.tri_range[-1]), int(t.outline_range[-1])]
    flat_f, flat_i = _flatten(floats, ints, counts)
    return PackedPieces(flat_f, flat_i, tuple(names), n_f)


@dataclass(frozen=True, eq=False)
class _FaceTables:
    """The per-piece and per-face sections :func:`_face_tables` fills (names as in
    :class:`PackedPieces`), with the exposed triangles' frames (``starts``/``inwards``) and outline
    segments (``out_a``/``out_b``) of the mixed faces, one array per face, in order."""

    normals: np.ndarray
    offsets: np.ndarray
    label: np.ndarray
    name: np.ndarray
    eps: np.ndarray
    edge_range: np.ndarray
    tri_range: np.ndarray
    outline_range: np.ndarray
    starts: list[np.ndarray]
    inwards: list[np.ndarray]
    out_a: list[np.ndarray]
    out_b: list[np.ndarray]


def _face_tables(pieces: Sequence[Piece], n_f: int, face_id: dict[str, int]) -> _FaceTables:
    """The faces of ``pieces`` padded to ``n_f`` per piece: planes, labels, face ids, tolerances and
    the ranges into edges, exposed triangles and outlines."""
    n_p = len(pieces)
    t = _FaceTables(
        normals=np.zeros((n_p, n_f, 3)),
        offsets=np.full((n_p, n_f), 1e9),
        label=np.zeros((n_p, n_f), np.int64),
        name=np.full((n_p, n_f), -1, np.int64),
        eps=np.zeros(n_p),
        edge_range=np.zeros(n_p + 1, np.int64),
        tri_range=np.zeros(n_p * n_f + 1, np.int64),
        outline_range=np.zeros(n_p * n_f + 1, np.int64),
        starts=[],
        inwards=[],
        out_a=[],
        out_b=[],
    )
    for k, p in enumerate(pieces):
        t.eps[k] = 1e-9 * max(float(np.ptp(p.vertices, axis=0).max()), 1e-3)
        t.edge_range[k + 1] = t.edge_range[k] + len(p.edge_a)
        for f, pf in enumerate(p.faces):
            t.normals[k, f], t.offsets[k, f] = pf.normal, pf.offset
            if pf.face is not None and pf.label != "internal":
                t.name[k, f] = face_id[pf.face]
                t.label[k, f] = EXTERNAL if pf.label == "external" else MIXED
            j = k * n_f + f
            t.tri_range[j + 1] = t.tri_range[j]
            t.outline_range[j + 1] = t.outline_range[j]
            if t.label[k, f] == MIXED:
                _add_exposed(t, j, np.asarray(pf.exposed, dtype=float).reshape(-1, 3, 3))
        for j in range(len(p.faces), n_f):  # padded faces: empty ranges
            t.tri_range[k * n_f + j + 1] = t.tri_range[k * n_f + j]
            t.outline_range[k * n_f + j + 1] = t.outline_range[k * n_f + j]
    return t


def _add_exposed(t: _FaceTables, j: int, tris: np.ndarray) -> None:
    """Add the exposed triangles ``tris`` (m,3,3) of mixed face ``j`` (``k * F + f``) and their
    outline to ``t``."""
    if len(tris):
        s, w = _tri_frames(tris)
        t.starts.append(s)
        t.inwards.append(w)
        t.tri_range[j + 1] += len(tris)
    a, b = _outline(tris)
    t.out_a.append(a)
    t.out_b.append(b)
    t.outline_range[j + 1] += len(a)


def _float_sections(pieces: Sequence[Piece], t: _FaceTables) -> list[np.ndarray]:
    """The float sections, in the order of :data:`FLOAT_SECTIONS`."""
    n_p = len(pieces)
    cat3 = lambda parts, shape: np.concatenate(parts).reshape(shape) if parts else np.zeros(shape)  # noqa: E731
    return [
        t.normals,
        t.offsets,
        np.array([p.lo for p in pieces]).reshape(-1, 3),
        np.array([p.hi for p in pieces]).reshape(-1, 3),
        t.eps,
        np.concatenate([p.edge_a for p in pieces]).reshape(-1, 3) if n_p else np.zeros((0, 3)),
        np.concatenate([p.edge_b for p in pieces]).reshape(-1, 3) if n_p else np.zeros((0, 3)),
        cat3(t.starts, (-1, 3, 3)) if t.starts else np.zeros((0, 3, 3)),
        cat3(t.inwards, (-1, 3, 3)) if t.inwards else np.zeros((0, 3, 3)),
        np.concatenate(t.out_a).reshape(-1, 3) if t.out_a else np.zeros((0, 3)),
        np.concatenate(t.out_b).reshape(-1, 3) if t.out_b else np.zeros((0, 3)),
    ]


def _int_sections(pieces: Sequence[Piece], object_names: Sequence[str], t: _FaceTables) -> list[np.ndarray]:
    """The integer sections, in the order of :data:`INT_SECTIONS`."""
    obj_index = {o: i for i, o in enumerate(object_names)}
    return [
        np.array([len(p.faces) for p in pieces], np.int64),
        t.label,
        t.name,
        np.array([obj_index[p.obj] for p in pieces], np.int64),
        t.edge_range,
        np.concatenate([np.asarray(p.edge_faces, np.int64).reshape(-1, 2) for p in pieces])
        if len(pieces)
        else np.zeros((0, 2), np.int64),
        t.tri_range,
        t.outline_range,
    ]


def _flatten(
    floats: list[np.ndarray], ints: list[np.ndarray], counts: list[int]
) -> tuple[np.ndarray, np.ndarray]:
    """The two flat arrays: the float sections one after the other, and the header (``counts``,
    then the sections' offsets) followed by the integer sections."""
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
    return flat_f, flat_i


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
