"""Generate the watertight polyhedral meshes of the built-in scenes (run from anywhere).

    .venv/bin/python scenes/make_meshes.py

Every mesh is a prism (a 2-D profile extruded along y) or a boolean of boxes, built with manifold3d,
in its own frame with the bottom at z = 0. The OBJ files are committed; this script documents them.
"""

from __future__ import annotations

import math
from pathlib import Path

import manifold3d as M
import numpy as np
import trimesh

from dlovr.geometry import prism_mesh

OUT = Path(__file__).resolve().parent / "meshes"


def to_trimesh(m: M.Manifold) -> trimesh.Trimesh:
    mm = m.to_mesh64()
    return trimesh.Trimesh(np.asarray(mm.vert_properties)[:, :3], np.asarray(mm.tri_verts), process=True)


def box(lo, hi) -> M.Manifold:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return M.Manifold.cube(list(hi - lo)).translate(list(lo))


def prism(profile_xz: list[tuple[float, float]], depth: float) -> M.Manifold:
    """Extrude a counter-clockwise (x, z) profile along y, centred on y = 0 (float64 throughout)."""
    m = prism_mesh(profile_xz, depth)
    return M.Manifold(M.Mesh64(vert_properties=m.vertices, tri_verts=m.faces.astype(np.uint64)))


def meshes() -> dict[str, trimesh.Trimesh]:
    out: dict[str, trimesh.Trimesh] = {}
    # peg_in_hole (world frame): a 6 cm high block beside the peg_in_hole block's +x side, wrapping
    # around its -y end; the hole (4 x 4 cm, 2 cm deep) lies just past that end, under the groove's end
    out["hole_block"] = to_trimesh(
        box([0.0, -0.1, 0], [0.16, 0.1, 0.06])
        + box([-0.06, -0.1, 0], [0.0, -0.045, 0.06])
        - box([-0.025, -0.085, 0.04], [0.015, -0.045, 0.07])
    )
    # l_block: paper Fig. 2, foot 30 x 20 x 6 cm, leg 10 x 20 x 16 cm
    out["l_block"] = to_trimesh(
        box([-0.15, -0.1, 0], [0.15, 0.1, 0.06]) + box([-0.15, -0.1, 0.06], [-0.05, 0.1, 0.16])
    )
    depth = 0.4
    # edges (paper Fig. 6 a-d); the cable lies on the left part (x < 0) parallel to the edge at x = 0
    # a) 90 deg concave: a floor plate with a wall
    out["edge_concave90"] = to_trimesh(
        prism([(-0.15, 0.0), (0.05, 0.0), (0.05, 0.1), (0.0, 0.1), (0.0, 0.02), (-0.15, 0.02)], depth)
    )
    # b) 175 deg concave: a plate whose top bends up by 5 deg at x = 0
    s5, c5 = math.sin(math.radians(5)), math.cos(math.radians(5))
    L2 = 0.08
    out["edge_concave175"] = to_trimesh(
        prism([(-0.15, 0.0), (L2 * c5, 0.0), (L2 * c5, 0.02 + L2 * s5), (0.0, 0.02), (-0.15, 0.02)], depth)
    )
    # c) 185 deg convex: the top bends down by 5 deg at x = 0, then steps down to a ledge
    h = 0.04
    out["edge_convex185"] = to_trimesh(
        prism(
            [
                (-0.15, 0.0),
                (0.12, 0.0),
                (0.12, 0.01),
                (L2 * c5, 0.01),
                (L2 * c5, h - L2 * s5),
                (0.0, h),
                (-0.15, h),
            ],
            depth,
        )
    )
    # d) 270 deg convex: a step; the upper top meets the riser at x = 0
    out["edge_convex270"] = to_trimesh(
        prism([(-0.15, 0.0), (0.1, 0.0), (0.1, 0.01), (0.0, 0.01), (0.0, 0.06), (-0.15, 0.06)], depth)
    )
    # corners: a plate with a V valley along y whose end is closed by a ramp (concave corners of three
    # faces that a cable can pass through with a small bend)
    out["valley175"] = valley_with_ramp(2.5, 10.0)  # valley 175°: semi-stable corner (E/VT, V/VT)
    out["valley152"] = valley_with_ramp(14.0, 10.0)  # valley 152°: stable corner (E/VS)
    return out


def valley_with_ramp(side_deg: float, ramp_deg: float) -> trimesh.Trimesh:
    """A 16 x 30 cm plate, 2 cm thick at its valley line x = 0 (along y); both sides rise at
    ``side_deg`` (opening angle 180 - 2 side_deg); from y = 0.05 on, a ramp rising at ``ramp_deg`` along
    +y closes the valley's end. The free space above is the intersection of the three half-spaces."""
    w, d, y0, h = 0.08, 0.3, 0.05, 0.02
    ts, tr = math.tan(math.radians(side_deg)), math.tan(math.radians(ramp_deg))
    valley = prism([(-w, 0.0), (w, 0.0), (w, h + w * ts), (0.0, h), (-w, h + w * ts)], d)
    # the ramp: a wedge in (y, z), extruded along x (built along y, then turned about z); it starts
    # 2 cm before y0 below the valley's surface
    y1, y2 = y0 - 0.02, d / 2
    ramp = prism([(y1, 0.0), (y2, 0.0), (y2, h + (y2 - y0) * tr), (y1, h + (y1 - y0) * tr)], 2 * w)
    return to_trimesh(valley + ramp.rotate([0.0, 0.0, 90.0]))


def main() -> None:
    OUT.mkdir(exist_ok=True)
    for name, m in meshes().items():
        assert m.is_watertight and m.volume > 0, name
        (OUT / f"{name}.obj").write_text(
            trimesh.exchange.obj.export_obj(m, digits=12, include_normals=False, include_texture=False)
        )
        print(f"{name}: {len(m.faces)} triangles")


if __name__ == "__main__":
    main()
