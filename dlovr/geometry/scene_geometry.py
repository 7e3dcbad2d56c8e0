"""World-frame geometry of a scene: :class:`SceneGeometry`.

Convex pieces with labelled faces (external / internal / mixed, mapped to object face names), the
per-object edge table, classification of cable points into environment primitives (closest point,
distance, active faces by a *tangential* tolerance; :mod:`dlovr.geometry.classify` and
:mod:`dlovr.geometry.labelling`), and the :class:`~dlovr.model.discrete.FactBook` (face normals,
concave/convex and opening angles of face pairs; :mod:`dlovr.geometry.facts`).

Typical use by the simulation::

    geom = SceneGeometry.from_scene(scene)
    sit = geom.situation(points)                 # topology.Situation (V_S gripped, end-vertex rule)
    disc = geom.discrete_situation(points)       # discrete.DiscreteSituation"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import trimesh

from dlovr.geometry.facts import SceneFactBook, _PairFacts
from dlovr.geometry.labelling import _Labelling
from dlovr.geometry.mesh import object_local_mesh
from dlovr.geometry.objects import GeomObject, build_object
from dlovr.geometry.packing import PackedPieces
from dlovr.model.discrete import DiscreteSituation, ModelParams, discretize
from dlovr.model.topology import Situation, as_vec3, situation_from_points
from dlovr.transforms import pose_matrix

if TYPE_CHECKING:
    from dlovr.scene import Scene


class SceneGeometry(_Labelling, _PairFacts):
    """World-frame geometry of a scene's objects (see the module docstring)."""

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
        self._packed: PackedPieces | None = None
        self._face_rows: dict[bytes, tuple[str, ...]] = {}

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
        objs = [
            build_object(
                o.name, object_local_mesh(o), pose_matrix(o.pos, o.quat), use_cache=use_cache,
                pieces=None if pieces is None else pieces[o.name],
            )
            for o in scene.objects
        ]
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

        ``V_S`` touches the gripper when ``gripped``; the end-vertex rule (docs/model.md, section 2) is
        applied by :func:`dlovr.model.topology.situation_from_points`.
        """
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(pts) < 2:
            raise ValueError("a cable polyline needs at least two points")
        z = as_vec3(gripper_z if gripper_z is not None else (0.0, 0.0, 1.0))
        return situation_from_points(
            self.point_primitives(pts, radius, contact_tol, tangential_tol),
            np.diff(pts, axis=0),
            self.face_normal,
            tip_angle_deg=self.params.tip_angle_deg,
            gripped=gripped,
            gripper_z=z,
        )

    def discrete_situation(self, points: np.ndarray, **kw) -> DiscreteSituation:
        """Discrete situation of a cable polyline: :meth:`situation`, then the model (docs/model.md, 3.2)."""
        return discretize(self.situation(points, **kw), self.fact_book(), self.params)

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
