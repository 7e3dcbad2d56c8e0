"""Labels of given (point, piece) pairs (:meth:`SceneGeometry.pair_hits`), how far each point may
move before they change (:meth:`SceneGeometry.label_slack`) and that slack split by direction
(:class:`LabelBudgets`), computed by the kernels of :mod:`dlovr.geometry.kernels`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dlovr.geometry import kernels
from dlovr.geometry.classify import _Classifier


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
        """Whether moving the points of pairs ``rows`` (indices or a mask) by ``moves`` ((m,3), m) keeps
        their labels."""
        rows = np.asarray(rows)
        rows = np.nonzero(rows)[0] if rows.dtype == bool else rows
        out = np.zeros(len(rows), dtype=bool)
        kernels.budgets_keep(
            self.table(), np.ascontiguousarray(rows, dtype=np.int64),
            np.ascontiguousarray(moves, dtype=float).reshape(-1, 3), out,
        )
        return out

    def table(self) -> np.ndarray:
        """The budgets as the kernels hold them: (K,6) rows of normal, along, across, any."""
        return np.column_stack([self.normal, self.along, self.across, self.any])

    @classmethod
    def from_table(cls, table: np.ndarray) -> LabelBudgets:
        """Budgets from (K,6) kernel rows (see :meth:`table`)."""
        t = np.asarray(table, dtype=float)
        return cls(t[:, :3].copy(), t[:, 3].copy(), t[:, 4].copy(), t[:, 5].copy())


class _Labelling(_Classifier):
    """Pair labelling of :class:`~dlovr.geometry.SceneGeometry` (a mixin)."""

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
        least its distance to the other face's plane), is decided from that face alone: a contact
        with it when it is exposed there (external, or the exposed part of a mixed face, and not
        covered by another object), else no contact with that piece. Points with any other pair
        (near an edge or a vertex) are classified as :meth:`classify_points` does.
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
        slack, budgets = out[5], out[6]
        assert slack is not None and budgets is not None  # computed: thresholds were given
        return (*out[:5], slack, budgets)

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
        pts = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
        pi = np.ascontiguousarray(point_idx, dtype=np.int64)
        pc = np.ascontiguousarray(piece_idx, dtype=np.int64)
        r = self.radius
        ttol = r / 5.0 if tangential_tol is None else float(tangential_tol)
        pk = self.packed()
        with_slack = thresholds is not None
        hit_i = np.empty((len(pi) + min(len(pts), len(pi)) * len(self.pieces), 2 + pk.width), np.int64)
        hit_f = np.empty((len(hit_i), 4))
        slack = np.full(len(pts), np.inf)
        table = np.empty((len(pi), 6))
        h = kernels.pair_hits(
            pk.floats, pk.ints, pts, pi, pc, r, r, float(contact_tol), ttol,
            np.asarray(thresholds or (), dtype=float), with_slack, False, hit_i, hit_f, slack, table,
        )
        faces = [self.face_tuple(hit_i[j, 2:]) for j in range(h)]
        out = (hit_i[:h, 0].copy(), hit_i[:h, 1].copy(), hit_f[:h, 0].copy(), faces, hit_f[:h, 1:].copy())
        if not with_slack:
            return (*out, None, None)
        return (*out, slack, LabelBudgets.from_table(table))
