"""The vector helpers of dlovr.transforms: the one zero-vector rule, and the same bits as the private
copies they replaced (their arithmetic, written out here)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from dlovr.model.derivation import _directions
from dlovr.model.detection import EDetector, Expectation
from dlovr.model.discrete import ModelParams, _point_or_line, contact_vector
from dlovr.model.facts import ContactFacts, FaceFact
from dlovr.transforms import angle_deg, norm, unit, units

_RNG = np.random.default_rng(26)
_VECTORS = _RNG.normal(size=(2000, 3)) * _RNG.uniform(1e-6, 1e3, size=(2000, 1))


def test_no_direction_is_none_a_zero_row_or_180_degrees():
    assert unit(np.zeros(3)) is None
    assert unit([0.0, 0.0, 1e-10], 1e-9) is None
    assert unit([0.0, 0.0, 1e-9], 1e-9) is not None  # below the tolerance only
    u = unit([0.0, 3.0, 4.0])
    assert u is not None and np.array_equal(u, [0.0, 0.6, 0.8])
    assert np.array_equal(units(np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 4.0]])), [[0, 0, 0], [0, 0.6, 0.8]])
    assert np.array_equal(units(np.zeros(3)), np.zeros(3))
    assert angle_deg(np.zeros(3), np.array([1.0, 0.0, 0.0])) == 180.0
    assert angle_deg(np.array([1.0, 0.0, 0.0]), np.array([0.0, 2.0, 0.0])) == 90.0


def test_the_helpers_round_as_the_copies_they_replaced():
    """``norm`` as ``np.sqrt((a * a).sum())`` (detection, derivation) and ``np.linalg.norm`` (discrete,
    geometry), ``unit`` as ``a / n``, ``angle_deg`` as detection's ``_angle_deg``: bit for bit."""
    for a, b in itertools.pairwise(_VECTORS):
        n = float(np.sqrt((a * a).sum()))
        assert norm(a) == n
        # np.linalg.norm sums by BLAS's dot, whose order follows the processor's SIMD width (AVX-512
        # machines round some of these vectors 1 ulp apart): equal but for that
        assert math.isclose(n, float(np.linalg.norm(a)), rel_tol=4 * np.finfo(float).eps)
        u = unit(a)
        assert u is not None and u.tobytes() == (a / n).tobytes()
        assert units(a).tobytes() == (a / np.linalg.norm(a, axis=-1, keepdims=True)).tobytes()
        c = float((a * b).sum()) / (n * float(np.sqrt((b * b).sum())))
        assert angle_deg(a, b) == math.degrees(math.acos(max(-1.0, min(1.0, c))))
    rows = units(_VECTORS)
    assert rows.tobytes() == (_VECTORS / np.linalg.norm(_VECTORS, axis=-1, keepdims=True)).tobytes()


def test_detection_and_derivation_drop_what_has_no_direction():
    """Their copies returned None below 1e-12 and 1e-9: a direction that short is not watched."""
    e = EDetector({}, Expectation(established=((0.0, 0.0, 1e-13), (0.0, 0.0, 1.0)), released=(None,)))
    assert [u.tolist() for u in e.dirs] == [[0.0, 0.0, -1.0]]
    dirs = _directions("E", [None, (1e-10, 0.0, 0.0)], [(0.0, 2.0, 0.0)], axes=[(0.0, 0.0, 1e-10)])
    assert [(u.tolist(), name) for u, name in dirs] == [([0.0, -1.0, 0.0], "-v")]


def test_the_classifier_still_refuses_a_zero_vector():
    """The discrete classifier's copy raised on a zero vector; it still does (and a zero gripper axis,
    which gave a NaN contact vector, is refused too: no reader or simulator makes one); a pinch
    (normals that cancel below the tolerance) still gives the zero contact vector."""
    with pytest.raises(ValueError, match="zero-length vector"):
        _point_or_line("S", [1.0, 0.0, 0.0], (0.0, 0.0, 0.0), ModelParams())
    with pytest.raises(ValueError, match="zero-length vector"):
        contact_vector(ContactFacts(faces=(), gripper_z=(0.0, 0.0, 0.0)), gripper=True)
    opposite = (FaceFact("a.F1", "a", (0.0, 0.0, 1.0)), FaceFact("b.F1", "b", (0.0, 0.0, -1.0)))
    assert contact_vector(ContactFacts(faces=opposite)).tolist() == [0.0, 0.0, 0.0]
