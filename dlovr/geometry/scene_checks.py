"""The checks of a scene that need its geometry: every object's mesh readable, watertight and not
self-intersecting, no two objects overlapping, the cable no longer than the scene.

:func:`dlovr.scene.load_scene` reads and checks a scene file without geometry; :func:`load_checked_scene`
adds these checks (what the command line, the browser UI and replay use). Every problem is a
:class:`dlovr.scene.SceneError`, ``<file>: <object or key>: <problem>``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from dlovr.geometry.mesh import MeshError, check_mesh, object_local_mesh, to_manifold
from dlovr.inputs import Fields
from dlovr.scene import Scene, SceneError, load_scene
from dlovr.transforms import pose_matrix

#: Relative common volume (of the smaller object) above which two objects overlap.
OVERLAP_TOL = 1e-9


def load_checked_scene(name_or_path: str | Path) -> Scene:
    """:func:`dlovr.scene.load_scene` and :func:`check_scene_geometry`."""
    scene = load_scene(name_or_path)
    check_scene_geometry(scene)
    return scene


def check_scene_geometry(scene: Scene) -> None:
    """Raise :class:`SceneError` when an object's mesh cannot be used, two objects overlap or the
    cable is longer than the scene's bounding box diagonal (world frame, metres)."""
    fields = Fields(scene.path, SceneError)
    worlds = [_world_mesh(fields, scene, i) for i in range(len(scene.objects))]
    solids = [(o.name, w, to_manifold(w)) for o, w in zip(scene.objects, worlds, strict=True)]
    for i in range(len(solids)):
        for j in range(i + 1, len(solids)):
            _check_overlap(fields, solids[i], solids[j])
    pts = [np.asarray(scene.gripper.pos)[None]] + [w.bounds for w in worlds]
    allp = np.vstack(pts)
    diag = float(np.linalg.norm(allp.max(axis=0) - allp.min(axis=0)))
    if worlds and scene.dlo.length > diag:
        raise fields.err(
            "dlo.length",
            f"cable of {scene.dlo.length:g} m is longer than the scene "
            f"(its bounding box diagonal is {diag:.3g} m)",
        )


def _world_mesh(fields: Fields, scene: Scene, index: int) -> trimesh.Trimesh:
    """Object ``index``'s checked mesh, placed in the world frame."""
    obj = scene.objects[index]
    try:
        local = object_local_mesh(obj)
    except MeshError as e:
        raise fields.err(f"object {obj.name!r}", str(e)) from None
    why = check_mesh(local)
    if why:
        raise fields.err(f"object {obj.name!r}", why)
    world = local.copy()
    world.apply_transform(pose_matrix(obj.pos, obj.quat))
    return world


def _check_overlap(
    fields: Fields, a: tuple[str, trimesh.Trimesh, Any], b: tuple[str, trimesh.Trimesh, Any]
) -> None:
    """Two objects (name, world mesh, its manifold) must not share volume (touching is fine)."""
    (na, wa, ma), (nb, wb, mb) = a, b
    lo = np.maximum(wa.bounds[0], wb.bounds[0])
    hi = np.minimum(wa.bounds[1], wb.bounds[1])
    if (hi - lo <= 0).any():
        return
    vol = (ma ^ mb).volume()
    if vol > OVERLAP_TOL * min(ma.volume(), mb.volume()) + 1e-12:
        raise fields.err(f"objects {na!r} and {nb!r}", f"overlap (common volume {vol:.3g} m^3)")
