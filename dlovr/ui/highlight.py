"""The faces in contact, drawn over the obstacles and coloured by the stability class of the contact
that touches them (light green stable, light yellow semi-stable, light red instable), and the face
labels (the *Face labels* option) that name every face and say which ones are touched."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from dlovr.geometry import SceneGeometry
from dlovr.model.discrete import Stability
from dlovr.ui.drawing import FACE_COLOR_BY_CLASS, STABILITY_WORDS

if TYPE_CHECKING:
    import viser

OFFSET = 0.0015
"""How far (m) a highlight is drawn out of its face, along the face's outward normal."""


class FaceHighlighter:
    """The highlighted faces and the face labels of the obstacles shown; drawn under the server's
    ``draw_lock``; ``scene`` gives the viser scene to draw into.

    :meth:`show` is given the faces of the moment shown (live or scrubbed); while ``pinned`` is set
    (a situation hovered in the timeline) those faces are shown instead.
    """

    def __init__(self, scene: Callable[[], viser.SceneApi]) -> None:
        self.scene = scene
        self._faces: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # name -> (triangles, normal)
        self._meshes: dict[str, Any] = {}
        self.labels: dict[str, Any] = {}
        self.shown: dict[str, Stability] = {}
        self.current: dict[str, Stability] = {}
        self.pinned: dict[str, Stability] | None = None

    def reset(self, geometry: SceneGeometry, labels: bool) -> None:
        """New obstacles (or the labels switched): forget the highlights, label the faces if asked."""
        for h in [*self._meshes.values(), *self.labels.values()]:
            h.remove()
        self._meshes, self.labels, self.shown = {}, {}, {}
        self.pinned = None  # a situation hovered over the old obstacles means nothing here
        self._faces = {
            name: (np.asarray(tris, dtype=float), np.asarray(normal, dtype=float))
            for obj in geometry.objects
            for name, tris, normal in zip(obj.face_names, obj.face_tris, obj.face_normals, strict=True)
        }
        if labels:
            api = self.scene()
            for name, (tris, normal) in self._faces.items():
                area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
                c3 = (tris.mean(axis=1) * area[:, None]).sum(axis=0) / max(area.sum(), 1e-12)
                obj = name.split(".", 1)[0]
                self.labels[name] = api.add_label(
                    f"/obstacles/{obj}_labels/{name}", name, position=tuple(c3 + 0.01 * normal)
                )
        self._draw(self.pinned if self.pinned is not None else self.current)

    def show(self, faces: dict[str, Stability]) -> None:
        """Highlight ``faces`` (name -> stability class) unless a hovered situation is pinned."""
        self.current = faces
        if self.pinned is None:
            self._draw(faces)

    def pin(self, faces: dict[str, Stability] | None) -> None:
        """Show ``faces`` whatever :meth:`show` is given, until ``pin(None)``."""
        self.pinned = faces
        self._draw(faces if faces is not None else self.current)

    def _draw(self, faces: dict[str, Stability]) -> None:
        faces = {f: c for f, c in faces.items() if f in self._faces}
        if faces == self.shown:
            return
        api = self.scene()
        for name in [n for n in self.shown if faces.get(n) != self.shown[n]]:
            self._meshes.pop(name).remove()
            if name in self.labels:
                self.labels[name].text = name
        for name, cls in faces.items():
            if name in self._meshes:
                continue
            tris, normal = self._faces[name]
            verts = (tris + OFFSET * normal).reshape(-1, 3).astype(np.float32)
            self._meshes[name] = api.add_mesh_simple(
                f"/contact_faces/{name}",
                verts,
                np.arange(len(verts), dtype=np.uint32).reshape(-1, 3),
                color=FACE_COLOR_BY_CLASS[cls],
                opacity=0.8,
                flat_shading=True,
                side="double",
            )
            if name in self.labels:
                self.labels[name].text = f"{name}: {STABILITY_WORDS[cls]}"
        self.shown = faces
