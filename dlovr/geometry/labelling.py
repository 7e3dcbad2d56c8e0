"""Labels of given (point, piece) pairs in one numpy pass (:meth:`SceneGeometry.pair_hits`), how
far each point may move before they change (:meth:`SceneGeometry.label_slack`) and that slack split
by direction (:class:`LabelBudgets`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dlovr.geometry.classify import _Classifier
from dlovr.geometry.vectors import _points_in_triangles


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


class _Labelling(_Classifier):
    """Pair labelling of :class:`~dlovr.geometry.SceneGeometry` (a mixin)."""

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
