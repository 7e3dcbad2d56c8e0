"""Polyhedral environment geometry: the scene's objects as the contact model sees them.

Pure: numpy, scipy, trimesh, manifold3d and (as a fallback) coacd. No simulator, no UI. Modules:

- :mod:`~dlovr.geometry.mesh`: mesh checks (:func:`check_mesh`), manifold3d conversion, primitives
  (:func:`box_mesh`, :func:`prism_mesh`) and a scene object's mesh in its own frame
  (:func:`object_local_mesh`, :class:`MeshError`).
- :mod:`~dlovr.geometry.faces`: an object's faces, numbered ``F1…Fk`` from its own surface in its
  local frame (:func:`object_faces`).
- :mod:`~dlovr.geometry.decomposition`: exact convex decomposition, CoACD for meshes that are not
  polyhedral enough, and their disk cache (:func:`decompose`).
- :mod:`~dlovr.geometry.pieces`: world-frame convex pieces with faces labelled external, internal or
  mixed (:class:`Piece`).
- :mod:`~dlovr.geometry.objects`: objects with named faces, pieces and the edge table
  (:func:`build_object`, :func:`scene_pieces`).
- :mod:`~dlovr.geometry.classify`: classification of cable points into environment primitives
  (:class:`PointHit`, :func:`primitives_per_point`).
- :mod:`~dlovr.geometry.labelling`: labels of given (point, piece) pairs, their slack and
  :class:`LabelBudgets`.
- :mod:`~dlovr.geometry.facts`: the fact book of a scene: face normals, concave/convex and opening
  angles of face pairs (:class:`SceneFactBook`).
- :mod:`~dlovr.geometry.scene_geometry`: :class:`SceneGeometry`, all of the above for a scene.
- :mod:`~dlovr.geometry.scene_checks`: the checks of a scene file that need its meshes
  (``load_checked_scene``).
- :mod:`~dlovr.geometry.vectors`: small vector and polygon helpers (private).

Typical use by the simulation::

    geom = SceneGeometry.from_scene(scene)
    sit = geom.situation(points)                 # topology.Situation (V_S gripped, end-vertex rule)
    disc = geom.discrete_situation(points)       # discrete.DiscreteSituation
"""

from dlovr.geometry.classify import PointHit, point_primitives, primitives_per_point
from dlovr.geometry.decomposition import DecompositionError, cache_dir, decompose, decompose_exact
from dlovr.geometry.faces import ObjectFace, object_faces
from dlovr.geometry.facts import SceneFactBook
from dlovr.geometry.labelling import LabelBudgets
from dlovr.geometry.mesh import MeshError, box_mesh, check_mesh, object_local_mesh, prism_mesh, to_manifold
from dlovr.geometry.objects import EdgeInfo, GeomObject, build_object, scene_pieces
from dlovr.geometry.pieces import Piece, PieceFace
from dlovr.geometry.scene_geometry import SceneGeometry

__all__ = [
    "DecompositionError",
    "EdgeInfo",
    "GeomObject",
    "LabelBudgets",
    "MeshError",
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
    "object_local_mesh",
    "point_primitives",
    "primitives_per_point",
    "prism_mesh",
    "scene_pieces",
    "to_manifold",
]
