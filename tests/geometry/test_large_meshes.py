"""A large mesh loads once slowly and then from the cache: its self-intersection test and convex
decomposition are remembered by content, its faces and pieces are built without dense all-pairs
products, and each slow step says what it does (issue 31 item 15)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from dlovr import cache
from dlovr.geometry import decomposition, mesh, pieces
from dlovr.geometry.mesh import check_mesh


@pytest.fixture
def said(tmp_path, monkeypatch):
    monkeypatch.setenv("DLOVR_CACHE_DIR", str(tmp_path))
    lines: list[str] = []
    cache.set_reporter(lines.append)
    yield lines
    cache.set_reporter(None)


def test_a_large_mesh_s_self_intersection_test_is_remembered(said, monkeypatch):
    sphere = trimesh.creation.icosphere(subdivisions=3)  # 1,280 triangles
    assert len(sphere.faces) > mesh.CHECK_CACHE_TRIANGLES
    monkeypatch.setattr(mesh, "SLOW_TRIANGLES", 1000)
    assert check_mesh(sphere) is None
    assert said == ["self-intersection test of a mesh of 1,280 triangles (once: then cached)...",
                    said[1]] and said[1].endswith(" s") and ": done in " in said[1]

    def never(m):
        raise AssertionError("tested again")

    monkeypatch.setattr(mesh, "_self_intersects", never)
    assert check_mesh(sphere) is None  # from the cache
    moved = sphere.copy()
    moved.vertices[0] += 1e-12  # another mesh: tested
    with pytest.raises(AssertionError, match="tested again"):
        check_mesh(moved)


def test_a_failed_self_intersection_test_is_never_remembered(said, monkeypatch):
    sphere = trimesh.creation.icosphere(subdivisions=3)
    monkeypatch.setattr(mesh, "_self_intersects", lambda m: True)
    assert check_mesh(sphere) == "mesh is self-intersecting"
    assert not list(cache.cache_dir().glob("meshcheck-*"))


def test_a_large_decomposition_says_what_it_does(said, monkeypatch):
    monkeypatch.setattr(decomposition, "SLOW_TRIANGLES", 4)
    box = trimesh.creation.box(extents=[1.0, 2.0, 3.0])
    decomposition.decompose(box, use_cache=False)
    assert said[0] == "convex decomposition of a mesh of 12 triangles (once: then cached)..."
    assert ": done in " in said[1]


def test_face_pairs_are_the_dense_product_s():
    rng = np.random.default_rng(3)
    on_face = rng.random((60, 40)) < 0.1
    inc = on_face.astype(float)
    dense = np.nonzero(np.triu(inc @ inc.T, k=1) >= 1.5)
    first, second = pieces._face_pairs(on_face)
    assert first.tolist() == dense[0].tolist() and second.tolist() == dense[1].tolist()
