"""Compiled labelling kernels: which faces of the scene's convex pieces a cable point touches, and
how far it may move before that changes (world frame, metres).

They read the pieces packed by :func:`dlovr.geometry.packing.pack_pieces` (``gf``: floats, ``gi``:
integers) and write hits as rows: ``hit_i`` (point, piece id, face ids sorted, -1 padded) and
``hit_f`` (distance, closest point). :class:`dlovr.geometry.SceneGeometry` wraps them
(``classify_points``, ``pair_hits``, ``label_slack``); the contact tracker's kernel calls
:func:`pair_hits` on the steps that label points again.

Rounding: every dot product of three rounds as the numpy code these kernels replaced did, so that
they label exactly as it did: :func:`dot3` as ``np.einsum`` (the products of x and z summed first),
:func:`dot3f` as its matrix products did through the development machine's BLAS (fused
multiply-adds, x first; BLAS rounds differently on other processors, these kernels do not),
:func:`norm3` as ``np.linalg.norm``. Sums of forces round as numpy's pairwise ``sum`` (:func:`np_sum`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from dlovr.geometry.packing import (
    E_,
    EXTERNAL,
    F_,
    FLOAT_SECTIONS,
    HEAD,
    INT_SECTIONS,
    INTERNAL,
    MIXED,
    O_,
    P_,
    T_,
)
from dlovr.jit import check_cache, fma, njit

# the header's offsets (packing's layout): the float sections' and their end, then the integer ones'
_N_FO, _N_IO = len(FLOAT_SECTIONS) + 1, len(INT_SECTIONS) + 1
_FO, _IO = HEAD, HEAD + _N_FO
_INF = np.inf

# --------------------------------------------------------------------------------------------------
# arithmetic


@njit(inner=True)
def dot3(ax: float, ay: float, az: float, bx: float, by: float, bz: float) -> float:
    """Dot product rounded as ``np.einsum`` rounds a contraction of three (x and z first)."""
    return (ax * bx + az * bz) + ay * by


@njit(inner=True)
def dot3f(ax: float, ay: float, az: float, bx: float, by: float, bz: float) -> float:
    """Dot product rounded as BLAS's matrix product (fused multiply-adds, x first)."""
    return fma(az, bz, fma(ay, by, ax * bx))  # type: ignore[call-arg]  # numba's stubs ask for typingctx too


@njit(inner=True)
def norm3(x: float, y: float, z: float) -> float:
    """Euclidean length rounded as ``np.linalg.norm`` (squares summed in order)."""
    return np.sqrt((x * x + y * y) + z * z)


@njit
def np_sum(a: np.ndarray) -> float:
    """``a.sum()`` rounded as numpy rounds it for a 1-D array: pairwise summation, halving blocks of
    more than 128 at a multiple of 8, blocks summed with 8 accumulators (fewer than 8: in order)."""
    start = np.int64(0)  # not a literal: one compilation of _block_sum
    if a.shape[0] <= 128:
        return 0.0 + block_sum(a, start, a.shape[0])
    # the halving, without recursion: a stack of (start, length, right half pending, left sum)
    los, ns = np.empty(64, np.int64), np.empty(64, np.int64)
    right, part = np.zeros(64, np.bool_), np.empty(64)
    top = 0
    los[0], ns[0] = 0, a.shape[0]
    while True:
        lo, m = los[top], ns[top]
        if m > 128:  # split: the left half first
            half = m // 2
            half -= half % 8
            right[top] = False
            top += 1
            los[top], ns[top] = lo, half
            continue
        v = block_sum(a, lo, m)
        while True:  # hand the sum up
            top -= 1
            if top < 0:
                return 0.0 + v
            if not right[top]:
                part[top], right[top] = v, True
                half = ns[top] // 2
                half -= half % 8
                los[top + 1], ns[top + 1] = los[top] + half, ns[top] - half
                top += 1
                break
            v = part[top] + v


@njit(inner=True)
def block_sum(a: np.ndarray, lo: int, n: int) -> float:
    """numpy's sum of ``a[lo : lo + n]`` for ``n`` up to 128 (without the initial 0.0 it adds)."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r = np.empty(8)
    for j in range(8):
        r[j] = a[lo + j]
    i = 8
    while i < n - (n % 8):
        for j in range(8):
            r[j] += a[lo + i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


class Pieces(NamedTuple):
    """The sections of the packed pieces (:func:`unpack`; world frame, metres; see
    :class:`dlovr.geometry.packing.PackedPieces`), P pieces of at most F faces, E edges, T exposed
    triangles, O outline segments."""

    normals: np.ndarray  # (P,F,3) unit outward face normals
    offsets: np.ndarray  # (P,F) face plane offsets
    lo: np.ndarray  # (P,3) box
    hi: np.ndarray  # (P,3)
    eps: np.ndarray  # (P,) tolerance
    edge_a: np.ndarray  # (E,3) edge end points
    edge_b: np.ndarray  # (E,3)
    tri_start: np.ndarray  # (T,3,3) triangle edge start points
    tri_in: np.ndarray  # (T,3,3) triangle inward in-plane edge normals
    outline_a: np.ndarray  # (O,3) outline segment end points
    outline_b: np.ndarray  # (O,3)
    nfaces: np.ndarray  # (P,) faces per piece
    label: np.ndarray  # (P,F) EXTERNAL, INTERNAL or MIXED
    name: np.ndarray  # (P,F) face id, -1 for none
    owner: np.ndarray  # (P,) object index
    edge_range: np.ndarray  # (P+1,) each piece's edges
    edge_faces: np.ndarray  # (E,2) the two faces of each edge
    tri_range: np.ndarray  # (P*F+1,) each face's exposed triangles
    outline_range: np.ndarray  # (P*F+1,) each face's outline segments


@njit(inner=True)
def unpack(gf: np.ndarray, gi: np.ndarray) -> Pieces:
    """The sections of the packed pieces as views (see :class:`dlovr.geometry.packing.PackedPieces`)."""
    n_p, n_f, n_e, n_t, n_o = gi[P_], gi[F_], gi[E_], gi[T_], gi[O_]
    fo = gi[_FO : _FO + _N_FO]
    io = gi[_IO : _IO + _N_IO]
    return Pieces(
        gf[fo[0] : fo[1]].reshape((n_p, n_f, 3)),
        gf[fo[1] : fo[2]].reshape((n_p, n_f)),
        gf[fo[2] : fo[3]].reshape((n_p, 3)),
        gf[fo[3] : fo[4]].reshape((n_p, 3)),
        gf[fo[4] : fo[5]],
        gf[fo[5] : fo[6]].reshape((n_e, 3)),
        gf[fo[6] : fo[7]].reshape((n_e, 3)),
        gf[fo[7] : fo[8]].reshape((n_t, 3, 3)),
        gf[fo[8] : fo[9]].reshape((n_t, 3, 3)),
        gf[fo[9] : fo[10]].reshape((n_o, 3)),
        gf[fo[10] : fo[11]].reshape((n_o, 3)),
        gi[io[0] : io[1]],
        gi[io[1] : io[2]].reshape((n_p, n_f)),
        gi[io[2] : io[3]].reshape((n_p, n_f)),
        gi[io[3] : io[4]],
        gi[io[4] : io[5]],
        gi[io[5] : io[6]].reshape((n_e, 2)),
        gi[io[6] : io[7]],
        gi[io[7] : io[8]],
    )


# --------------------------------------------------------------------------------------------------
# primitives


@njit(inner=True)
def closest_on_segment(px: float, py: float, pz: float, a: np.ndarray, b: np.ndarray, e: int):
    """Closest point (x, y, z) on segment ``a[e]``-``b[e]`` to ``p`` and its distance."""
    ax, ay, az = a[e, 0], a[e, 1], a[e, 2]
    abx, aby, abz = b[e, 0] - ax, b[e, 1] - ay, b[e, 2] - az
    den = dot3(abx, aby, abz, abx, aby, abz)
    if den == 0.0:
        den = 1.0
    t = dot3(px - ax, py - ay, pz - az, abx, aby, abz) / den
    t = min(max(t, 0.0), 1.0)
    qx, qy, qz = ax + t * abx, ay + t * aby, az + t * abz
    return qx, qy, qz, norm3(px - qx, py - qy, pz - qz)


@njit(inner=True)
def in_triangles(
    qx: float, qy: float, qz: float, starts: np.ndarray, inwards: np.ndarray, t0: int, t1: int, tol: float
) -> bool:
    """Whether ``q`` (near their plane) lies in one of triangles ``t0``..``t1`` (edge start points and
    inward in-plane edge normals)."""
    for t in range(t0, t1):
        ok = True
        for e in range(3):
            s, w = starts[t, e], inwards[t, e]
            if dot3(qx - s[0], qy - s[1], qz - s[2], w[0], w[1], w[2]) < -tol:
                ok = False
                break
        if ok:
            return True
    return False


@njit(inner=True)
def outline_slack(qx: float, qy: float, qz: float, a: np.ndarray, b: np.ndarray, s0: int, s1: int) -> float:
    """How far ``q`` on a mixed face may move before it crosses its exposed part's outline (segments
    ``s0``..``s1``), less the tolerance of the in-triangle test (0 for a face without outline)."""
    if s1 == s0:
        return 0.0
    d = _INF
    for s in range(s0, s1):
        d = min(d, closest_on_segment(qx, qy, qz, a, b, s)[3])
    return max(d - 1e-8, 0.0)


@njit(inner=True)
def inside_other(
    qx: float, qy: float, qz: float, obj: int, margin: float, normals: np.ndarray, offsets: np.ndarray,
    nfaces: np.ndarray, owner: np.ndarray,
) -> bool:
    """Whether ``q`` lies inside (deeper than ``margin``) a piece of an object other than ``obj``."""
    for k in range(nfaces.shape[0]):
        if owner[k] == obj:
            continue
        inside = True
        for f in range(nfaces[k]):
            n = normals[k, f]
            if not dot3f(qx, qy, qz, n[0], n[1], n[2]) - offsets[k, f] < -margin:
                inside = False
                break
        if inside:
            return True
    return False


@njit(inner=True)
def cover_margin(
    qx: float, qy: float, qz: float, obj: int, normals: np.ndarray, offsets: np.ndarray, nfaces: np.ndarray,
    owner: np.ndarray,
):
    """For a free-side probe ``q`` of a face of object ``obj``: whether a piece of another object
    covers it (its largest plane residual below -1e-9) and how far it may move before that changes."""
    covered = False
    margin = _INF
    for k in range(nfaces.shape[0]):
        if owner[k] == obj:
            continue
        res = -_INF
        for f in range(nfaces[k]):
            n = normals[k, f]
            res = max(res, dot3(n[0], n[1], n[2], qx, qy, qz) - offsets[k, f])
        covered = covered or res < -1e-9
        margin = min(margin, abs(res + 1e-9))
    return covered, margin


# --------------------------------------------------------------------------------------------------
# classification of points against every piece


@njit(inner=True)
def classify_point(
    px: float,
    py: float,
    pz: float,
    point: int,
    gf: np.ndarray,
    gi: np.ndarray,
    r: float,
    radius: float,
    contact_tol: float,
    ttol: float,
    thresholds: np.ndarray,
    with_slack: bool,
    hit_i: np.ndarray,
    hit_f: np.ndarray,
    h: int,
):
    """Every piece point ``p`` touches (centerline within ``r + contact_tol``), written as hit rows
    from row ``h`` on; returns the next free row and the slack of the decisions (inf without
    ``with_slack``). Active faces: the closest feature's and those of every edge within ``ttol`` of
    the closest point; internal faces, a mixed face's internal part and covered faces are dropped."""
    g = unpack(gf, gi)
    normals, offsets, lo, hi, eps_ = g.normals, g.offsets, g.lo, g.hi, g.eps
    edge_a, edge_b = g.edge_a, g.edge_b
    starts, inwards, out_a, out_b = g.tri_start, g.tri_in, g.outline_a, g.outline_b
    nfaces, label, name, owner, edge_range = g.nfaces, g.label, g.name, g.owner, g.edge_range
    edge_faces, tri_range, out_range = g.edge_faces, g.tri_range, g.outline_range
    n_f = normals.shape[1]
    reach = r + contact_tol
    slack = _INF
    res = np.empty(n_f)
    proj = np.empty((n_f, 3))
    active = np.zeros(n_f, np.bool_)
    width = hit_i.shape[1] - 2
    for k in range(nfaces.shape[0]):
        out = -_INF
        for c, v in enumerate((px, py, pz)):
            out = max(out, max((lo[k, c] - reach) - v, (v - hi[k, c]) - reach))
        if not out <= 0.0:  # outside the piece's box (+ reach): its distance to go before it counts
            slack = min(slack, out)
            continue
        fk, eps = nfaces[k], eps_[k]
        inside = True
        for f in range(fk):
            n = normals[k, f]
            res[f] = dot3f(px, py, pz, n[0], n[1], n[2]) - offsets[k, f]
            proj[f, 0], proj[f, 1], proj[f, 2] = px - res[f] * n[0], py - res[f] * n[1], pz - res[f] * n[2]
            inside = inside and res[f] <= 0.0
        best_f, bf = 0, _INF
        for f in range(fk):
            valid = True
            for gg in range(fk):
                m = normals[k, gg]
                if not dot3(proj[f, 0], proj[f, 1], proj[f, 2], m[0], m[1], m[2]) - offsets[k, gg] <= eps:
                    valid = False
                    break
            fd = res[f] if valid and res[f] >= -eps else _INF
            if fd < bf:
                best_f, bf = f, fd
        be = _INF  # the nearest edge (the first of equals) and its closest point
        qex = qey = qez = 0.0
        for e in range(edge_range[k], edge_range[k + 1]):
            x, y, z, d = closest_on_segment(px, py, pz, edge_a, edge_b, e)
            if d < be:
                be, qex, qey, qez = d, x, y, z
        use_face = bf <= be
        if use_face:
            qx, qy, qz, dist = proj[best_f, 0], proj[best_f, 1], proj[best_f, 2], bf
        else:
            qx, qy, qz, dist = qex, qey, qez, be
        margin = 0.0
        if with_slack:  # inside the piece: no bound; else the distance against reach
            maxres = -_INF
            for f in range(fk):
                maxres = max(maxres, res[f])
            margin = 0.0 if maxres <= 0.0 else min(maxres, abs(dist - reach))
        if inside:  # inside points: the nearest face plane
            jin = 0
            for f in range(1, fk):
                if res[f] > res[jin]:
                    jin = f
            qx, qy, qz, dist = proj[jin, 0], proj[jin, 1], proj[jin, 2], res[jin]
            best_f, use_face = jin, True
        if not dist <= reach:
            slack = min(slack, margin)
            continue
        for f in range(n_f):
            active[f] = False
        if use_face:
            active[best_f] = True
        mc = margin
        for e in range(edge_range[k], edge_range[k + 1]):
            dq = closest_on_segment(qx, qy, qz, edge_a, edge_b, e)[3]
            if dq <= ttol:
                active[edge_faces[e, 0]] = True
                active[edge_faces[e, 1]] = True
            mc = min(mc, abs(dq - ttol))
        start = h
        for f in range(fk):
            if not active[f] or label[k, f] == INTERNAL:
                continue
            j = k * n_f + f
            n = normals[k, f]
            ok = True
            if label[k, f] == MIXED:
                ok = in_triangles(qx, qy, qz, starts, inwards, tri_range[j], tri_range[j + 1], max(eps, 1e-9))
            two_r = 2.0 * radius
            bx, by, bz = qx + two_r * n[0], qy + two_r * n[1], qz + two_r * n[2]
            ok = ok and not inside_other(bx, by, bz, owner[k], 1e-9, normals, offsets, nfaces, owner)
            if with_slack:
                if label[k, f] == MIXED:
                    mc = min(mc, outline_slack(qx, qy, qz, out_a, out_b, out_range[j], out_range[j + 1]))
                mc = min(mc, cover_margin(bx, by, bz, owner[k], normals, offsets, nfaces, owner)[1])
            if ok:
                h = _add_face(hit_i, start, h, width, name[k, f], point, k)
        if h > start:  # one hit row, its faces sorted and once each
            hit_f[start, 0], hit_f[start, 1], hit_f[start, 2], hit_f[start, 3] = dist, qx, qy, qz
            h = start + 1
        if with_slack:
            for t in thresholds:
                mc = min(mc, abs(dist - t))
            slack = min(slack, mc)
    return h, slack


@njit(inner=True)
def _add_face(hit_i: np.ndarray, row: int, h: int, width: int, face: int, point: int, piece: int) -> int:
    """Insert face id ``face`` into the sorted face list of hit row ``row`` (``h > row``: the row is
    started); returns ``row + 1``."""
    if h == row:
        hit_i[row, 0], hit_i[row, 1] = point, piece
        for c in range(2, hit_i.shape[1]):
            hit_i[row, c] = -1
    faces = hit_i[row, 2:]
    for i in range(width):
        if faces[i] == face:
            break
        if faces[i] < 0 or faces[i] > face:
            for j in range(width - 1, i, -1):
                faces[j] = faces[j - 1]
            faces[i] = face
            break
    return row + 1


# --------------------------------------------------------------------------------------------------
# labels of given (point, piece) pairs


@njit
def pair_hits(
    gf: np.ndarray,
    gi: np.ndarray,
    pts: np.ndarray,
    pi: np.ndarray,
    pc: np.ndarray,
    r: float,
    radius: float,
    contact_tol: float,
    ttol: float,
    thresholds: np.ndarray,
    with_slack: bool,
    every_piece: bool,
    hit_i: np.ndarray,
    hit_f: np.ndarray,
    slack: np.ndarray,
    budgets: np.ndarray,
) -> int | np.int64:
    """Hits of the (point ``pi``, piece ``pc``) pairs, sorted by point then piece; returns their count.
    ``radius``: the cable's (its free-side probes); ``r``: the one the contact distance
    ``r + contact_tol`` is measured with; ``every_piece``: classify each point of ``pi`` against
    every piece (:func:`classify_point`) instead.

    A pair whose closest point lies inside one face, at least ``ttol`` from its other planes, is
    decided here: a contact with that face when it is exposed there (external, or the exposed part
    of a mixed face, and not covered by another object), else no contact with that piece. Points with
    any other pair (near an edge or a vertex) are classified against every piece
    (:func:`classify_point`). ``hit_i`` needs ``len(pi)`` rows plus one per piece for each point.

    With ``with_slack``: ``slack`` (one per point of ``pts``) gets how far each point may move
    before its labels or its side of a distance in ``thresholds`` could change (inf for points not
    queried), and ``budgets`` (one row per pair) that slack split by direction: the unit normal of
    the pair's nearest plane, the budget along it, across it and in all (see
    :class:`dlovr.geometry.LabelBudgets`).
    """
    g = unpack(gf, gi)
    normals, offsets, label, name, owner, nfaces = g.normals, g.offsets, g.label, g.name, g.owner, g.nfaces
    starts, inwards, out_a, out_b = g.tri_start, g.tri_in, g.outline_a, g.outline_b
    tri_range, out_range = g.tri_range, g.outline_range
    n_f = normals.shape[1]
    k_n = 0 if every_piece else pi.shape[0]
    reach = r + contact_tol
    width = hit_i.shape[1] - 2
    res = np.empty(n_f)
    rb = np.empty(k_n)
    best = np.empty(k_n, np.int64)
    q = np.empty((k_n, 3))
    take = np.zeros(k_n, np.bool_)
    amb = np.zeros(pts.shape[0], np.bool_)
    if with_slack:
        for i in range(slack.shape[0]):
            slack[i] = _INF
    if every_piece:
        for i in pi:
            amb[i] = True
    for j in range(k_n):
        k, p = pc[j], pts[pi[j]]
        fk = nfaces[k]
        b = 0
        for f in range(fk):
            n = normals[k, f]
            res[f] = dot3(n[0], n[1], n[2], p[0], p[1], p[2]) - offsets[k, f]
            if res[f] > res[b]:
                b = f
        rbj = res[b]
        nb = normals[k, b]
        rq, second = -_INF, -_INF
        for f in range(fk):
            if f != b:
                n = normals[k, f]
                rq = max(rq, res[f] - rbj * dot3(n[0], n[1], n[2], nb[0], nb[1], nb[2]))
                second = max(second, res[f])
        qx, qy, qz = p[0] - rbj * nb[0], p[1] - rbj * nb[1], p[2] - rbj * nb[2]
        far = rbj > reach
        interior = rq <= -ttol and not far
        lab = label[k, b]
        exposed = interior and lab == EXTERNAL
        mixed = False
        if interior and lab != EXTERNAL:
            mixed = lab == MIXED
            t0, t1 = tri_range[k * n_f + b], tri_range[k * n_f + b + 1]
            exposed = mixed and in_triangles(qx, qy, qz, starts, inwards, t0, t1, 1e-9)
        probed = interior and (lab == EXTERNAL or mixed) if with_slack else exposed
        cover = _INF
        if probed:
            two_r = 2.0 * radius
            bx, by, bz = qx + two_r * nb[0], qy + two_r * nb[1], qz + two_r * nb[2]
            covered, cover = cover_margin(bx, by, bz, owner[k], normals, offsets, nfaces, owner)
            exposed = exposed and not covered
        if not (far or interior):
            amb[pi[j]] = True
        take[j] = exposed and rbj <= reach
        rb[j], best[j] = rbj, b
        q[j, 0], q[j, 1], q[j, 2] = qx, qy, qz
        if with_slack:
            along = _INF if far else abs(rbj - reach)
            across = _INF if far else abs(rq + ttol)
            whole = rbj - reach if far else (rbj - second) / 2.0
            if interior and mixed:
                s0, s1 = out_range[k * n_f + b], out_range[k * n_f + b + 1]
                across = min(across, outline_slack(qx, qy, qz, out_a, out_b, s0, s1))
            if probed:
                across = min(across, cover)
                for t in thresholds:
                    along = min(along, abs(rbj - t))
            budgets[j, 0], budgets[j, 1], budgets[j, 2] = nb[0], nb[1], nb[2]
            budgets[j, 3], budgets[j, 4], budgets[j, 5] = along, across, whole
            slack[pi[j]] = min(slack[pi[j]], min(min(along, across), whole))
    h = np.int64(0)  # not a literal: a literal would compile the callees twice
    for j in range(k_n):
        if take[j] and not amb[pi[j]]:
            hit_i[h, 0], hit_i[h, 1] = pi[j], pc[j]
            for c in range(3, hit_i.shape[1]):
                hit_i[h, c] = -1
            hit_i[h, 2] = name[pc[j], best[j]]
            hit_f[h, 0], hit_f[h, 1], hit_f[h, 2], hit_f[h, 3] = rb[j], q[j, 0], q[j, 1], q[j, 2]
            h += 1
    for i in range(pts.shape[0]):
        if amb[i]:
            h, si = classify_point(
                pts[i, 0], pts[i, 1], pts[i, 2], i, gf, gi, r, radius, contact_tol, ttol, thresholds,
                with_slack, hit_i, hit_f, h,
            )
            if with_slack:
                slack[i] = min(slack[i], si)
    if with_slack:  # near an edge or vertex: the point's slack, in every direction
        for j in range(k_n):
            if amb[pi[j]]:
                budgets[j, 3], budgets[j, 4], budgets[j, 5] = _INF, _INF, slack[pi[j]]
    _sort_hits(hit_i, hit_f, h, width)
    return h


@njit(inner=True)
def _sort_hits(hit_i: np.ndarray, hit_f: np.ndarray, h: int, width: int) -> None:
    """Sort the first ``h`` hit rows by point, then piece (stable; an insertion sort: the rows come
    nearly sorted)."""
    for a in range(1, h):
        b = a
        while b > 0 and (hit_i[b - 1, 0], hit_i[b - 1, 1]) > (hit_i[b, 0], hit_i[b, 1]):
            for c in range(2 + width):
                hit_i[b - 1, c], hit_i[b, c] = hit_i[b, c], hit_i[b - 1, c]
            for c in range(4):
                hit_f[b - 1, c], hit_f[b, c] = hit_f[b, c], hit_f[b - 1, c]
            b -= 1


@njit
def budgets_keep(budgets: np.ndarray, rows: np.ndarray, moves: np.ndarray, out: np.ndarray) -> None:
    """Whether moving the points of pairs ``rows`` by ``moves`` keeps their labels (under the
    budgets along the pair's normal, across it and in all; see :class:`dlovr.geometry.LabelBudgets`)."""
    for i in range(rows.shape[0]):
        out[i] = keeps(budgets, rows[i], moves[i, 0], moves[i, 1], moves[i, 2])


@njit(inner=True)
def keeps(budgets: np.ndarray, j: int, mx: float, my: float, mz: float) -> bool:
    """Whether a move ``m`` keeps the labels of the pair with budget row ``j``."""
    d2 = dot3(mx, my, mz, mx, my, mz)
    dn = dot3(mx, my, mz, budgets[j, 0], budgets[j, 1], budgets[j, 2])
    dn2 = dn * dn
    any_, along, across = budgets[j, 5], budgets[j, 3], budgets[j, 4]
    return d2 < any_ * any_ and dn2 < along * along and d2 - dn2 < across * across


@njit
def inside_other_points(
    gf: np.ndarray, gi: np.ndarray, q: np.ndarray, obj: int, margin: float, out: np.ndarray
) -> None:
    """:func:`inside_other` for every point of ``q`` (into ``out``)."""
    g = unpack(gf, gi)
    for i in range(q.shape[0]):
        out[i] = inside_other(q[i, 0], q[i, 1], q[i, 2], obj, margin, g.normals, g.offsets, g.nfaces, g.owner)


check_cache(__name__)
