"""Compile the per-step kernels once per installation, before an interactive session needs them.

numba compiles a kernel at its first call and caches it on disk (:mod:`dlovr.jit`): the first run of
dlovr on a machine spends some seconds compiling, later runs load the cache. :func:`warm_up` does it
up front (``dlovr serve`` and ``dlovr demo`` call it and say so), by running every kernel once on the
built-in table scene. Compiled kernels go into the machine's kernel store (:func:`dlovr.jit.keep_in_store`),
from which a new installation with the same kernels takes them instead of compiling.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

NOTICE = "compiling kernels (first run only)"


def warm_up(say: Callable[[str], None] | None = None, *, force: bool = False) -> float:
    """Compile the kernels unless this installation has them already (``force``: run them anyway);
    ``say`` gets :data:`NOTICE` first. Returns the seconds it took (0 when they were compiled)."""
    from dlovr.jit import keep_in_store, kernels_warm, mark_kernels_warm
    from dlovr.sim import track_kernels  # noqa: F401  (imports every kernel module; its cache tells)

    if not force and kernels_warm():
        keep_in_store()
        return 0.0
    if say is not None:
        say(NOTICE)
    t0 = time.perf_counter()
    _run_every_kernel()
    mark_kernels_warm()
    keep_in_store()
    return time.perf_counter() - t0


def _run_every_kernel() -> None:
    """Every kernel once, with the argument types of a real run: a tracked simulation of the table
    scene until the cable lies on the table, one step with a point moved (labelled again alone), and
    the geometry's own queries."""
    from dlovr.geometry import SceneGeometry
    from dlovr.scene import load_scene, scenes_dir
    from dlovr.script import load_script
    from dlovr.sim import kernels
    from dlovr.sim.simulator import Simulator

    scene = load_scene("table")
    sim = Simulator(scene, track=True)
    tracker = sim.tracker
    rec = None
    for rec in sim.run(load_script(scenes_dir() / "table.script.toml")):
        if len(rec.contact_arrays) and tracker.labellings and tracker.current.forces:
            break
    assert rec is not None
    moved = rec.points.copy()
    moved[-1] += 0.002  # beyond its slack: that point alone is labelled again
    tracker.update(replace(rec, points=moved))
    tracker.update(replace(rec, contact_arrays=None))  # no contact arrays: every pair
    kernels.self_pairs(0, np.zeros(0), sim._views.cfg, np.zeros((0, 2), np.int64))
    q = np.array([1.0, 0.0, 0.0, 0.0])
    kernels.move_gripper(np.zeros(3), q.copy(), np.zeros(3), q, 0.0, 0.0)  # a target assigned, writeable
    geom: SceneGeometry = tracker.geometry
    pts = np.array([[0.0, 0.0, geom.radius], [0.3, 0.2, 0.1]])
    geom.classify_points(pts)
    pairs = np.array([0, 1]), np.array([0, 0])
    budgets = geom.pair_hits_and_slack(pts, *pairs, 1e-3, None, (0.0,))[6]
    budgets.keeps(np.array([0]), np.zeros((1, 3)))
    geom._inside_other(pts, geom.objects[0].name, 1e-9)
