"""Loading a scene with a large mesh: the scene checks and the scene geometry (convex pieces, their
faces labelled against the object's faces, their edges), for icospheres of 320 to 5120 triangles.

Run: ``.venv/bin/python benchmarks/bench_mesh.py [--max-subdivisions 4]``

Issue 31 measured 65-75 s of CPU for a 5,120-triangle mesh (the limit is 20,000) on every load: the
pieces' faces and edges were matched in Python loops over every pair of hull facets. Prints CPU
seconds (``time.process_time``) per size; the decomposition itself is cached on disk (a private,
temporary cache here, so the first load of each size includes it).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-subdivisions", type=int, default=4)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["DLOVR_CACHE_DIR"] = str(Path(tmp) / "cache")
        import trimesh

        from dlovr.geometry import SceneGeometry
        from dlovr.geometry.scene_checks import load_checked_scene

        template = (ROOT / "scenes" / "l_block.toml").read_text()
        (Path(tmp) / "meshes").mkdir()
        for sub in range(2, args.max_subdivisions + 1):
            mesh = trimesh.creation.icosphere(subdivisions=sub, radius=0.05)
            mesh.export(Path(tmp) / "meshes" / f"ico{sub}.obj")
            scene_file = Path(tmp) / f"ico{sub}.toml"
            scene_file.write_text(
                template.replace("meshes/l_block.obj", f"meshes/ico{sub}.obj").replace(
                    "pos = [0.1, 0.0, 0.0]", "pos = [0.1, 0.0, 0.05]"
                )
            )
            c0 = time.process_time()
            scene = load_checked_scene(scene_file)
            c1 = time.process_time()
            SceneGeometry.from_scene(scene)
            c2 = time.process_time()
            SceneGeometry.from_scene(scene)  # the decomposition now from the cache
            c3 = time.process_time()
            print(
                f"{len(mesh.faces):5d} triangles: checks {c1 - c0:6.2f} s, geometry {c2 - c1:6.2f} s "
                f"(first), {c3 - c2:6.2f} s (cached decomposition)  [CPU]"
            )


if __name__ == "__main__":
    main()
