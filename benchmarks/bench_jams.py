"""Jams under MuJoCo's contact settings: how deep a cable sinks where it is wedged or struck, whether
the run diverges, and what bare ``mj_step`` costs (docs/recordings.md, "Reducing jams").

Run: ``.venv/bin/python benchmarks/bench_jams.py [--settings JSON ...] [--cases NAME ...]
[--timing CASE] [--repeat 3]``

Each ``--settings`` is a JSON object of what to change from the project's model (``dlovr/sim/build.py``):
``solimp``, ``solref`` (the contacts'), ``timestep``, ``impratio``, ``cone`` (``mjCONE_ELLIPTIC``),
``iterations``, ``ls_iterations``, ``noslip_iterations``, ``diagexact``, ``speculative``. ``{}`` is the
model as it is; the default compares it with the contacts' impedance before the change
(``{"solimp": [0.95, 0.99, 0.001, 0.5, 2]}``).

The cases: ``v60_along25`` / ``v60_along40`` (a 12 cm cable of 1 GPa lying along a 60° V groove, its
held end pushed 25 / 40 mm into the V: the wedge of ``tests/sim/v_groove_scenes.py``),
``v60_along40_soft`` (a 20 MPa cable), ``v60_along60`` (the script's 60 mm, of which the gripper's top
speed leaves about 55 mm), ``v90_along40``,
``v60_down25`` / ``v60_down50`` (hanging, pushed tip first into the V), ``v60_across25`` (across the V,
the held end pressed 25 mm into the flank), ``table_strike`` (the 0.6 m table cable lowered at top speed
until its tip strikes the table and beyond: ``tests/sim/test_sim.py``), and any built-in demonstration
(``peg_in_hole``, ``table``, ...). Per case and setting it prints the deepest penetration (mm), the
largest segment squeeze or stretch, the fastest point (m/s), the steps run and the divergence if any.

``--timing CASE`` also times bare ``mj_step`` (thread CPU, median of ``--repeat`` interleaved rounds) on
each setting's model along the gripper path that the case's run took.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

import dlovr.sim.build as build
from dlovr.scene import load_scene, scenes_dir
from dlovr.script import load_script
from dlovr.sim import SimulationDiverged, Simulator

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "sim"))
from v_groove_scenes import v_groove  # pyright: ignore[reportMissingImports]  (the tests' scene writer)

BEFORE = {"solimp": [0.95, 0.99, 0.001, 0.5, 2]}
CASES = (
    "v60_along25", "v60_along40", "v60_along40_soft", "v90_along40", "v60_down25", "v60_across25",
    "table_strike",
)
V_CASES = {  # opening (deg), Young's modulus, x0, press (m), pose
    "v60_along25": (60.0, 1e9, -0.06, 0.025, "along"),
    "v60_along40": (60.0, 1e9, -0.06, 0.040, "along"),
    "v60_along60": (60.0, 1e9, -0.06, 0.060, "along"),  # the gripper's top speed leaves it about 55 mm
    "v60_along40_soft": (60.0, 2e7, -0.06, 0.040, "along"),
    "v90_along40": (90.0, 1e9, -0.06, 0.040, "along"),
    "v60_down25": (60.0, 1e9, 0.0, 0.025, "down"),
    "v60_down50": (60.0, 1e9, 0.0, 0.050, "down"),
    "v60_across25": (60.0, 1e9, -0.03, 0.025, "across"),
}
STRIKE = dict(zip([19, 33, 150, 160, 314, 333], np.linspace(0.7, 0.3, 6).tolist(), strict=True))


@contextmanager
def settings_applied(settings: dict[str, Any]) -> Iterator[None]:
    """Models built inside use ``settings`` (see the module's docstring)."""
    saved = build.CONTACT_SOLIMP, build.CONTACT_SOLREF, build._set_options
    original = build._set_options

    def options(spec: mujoco.MjSpec, timestep: float, gravity: Any) -> None:
        original(spec, settings.get("timestep", timestep), gravity)
        o = spec.option
        for key in ("impratio", "iterations", "ls_iterations", "noslip_iterations"):
            if key in settings:
                setattr(o, key, settings[key])
        if "cone" in settings:
            o.cone = getattr(mujoco.mjtCone, settings["cone"])
        for key, bit in (("diagexact", "mjENBL_DIAGEXACT"), ("speculative", "mjENBL_SPECULATIVE")):
            if settings.get(key):
                o.enableflags |= int(getattr(mujoco.mjtEnableBit, bit))

    build.CONTACT_SOLIMP = tuple(settings.get("solimp", saved[0]))
    build.CONTACT_SOLREF = tuple(settings.get("solref", saved[1]))
    build._set_options = options
    try:
        yield
    finally:
        build.CONTACT_SOLIMP, build.CONTACT_SOLREF, build._set_options = saved


def commands(case: str, tmp: Path) -> tuple[Simulator, Iterator[tuple[Any, Any]]]:
    """The case's simulator and its gripper targets, one (pos, quat or None) per step."""
    if case == "table_strike":
        sim = Simulator(load_scene("table"))
        target = [(0.0, 0.0, 0.7)]

        def strike() -> Iterator[tuple[Any, Any]]:
            for k in range(700):
                target[0] = (0.0, 0.0, STRIKE[k]) if k in STRIKE else target[0]
                yield (target[0] if k >= 19 else sim.target_pos), None

        return sim, strike()
    if case in V_CASES:
        opening, young, x0, press, pose = V_CASES[case]
        script_path = v_groove(tmp, opening, young, x0, press, 0.3, pose=pose)
        sim = Simulator(load_scene(tmp / "v.toml"))
    else:
        script_path = scenes_dir() / f"{case}.script.toml"
        sim = Simulator(load_scene(case))
    script = load_script(script_path)
    plan = script.plan(sim.data.mocap_pos[sim.built.mocap_id], sim.data.mocap_quat[sim.built.mocap_id])
    steps = round(script.total_duration / sim.model.opt.timestep)
    return sim, (plan.at(k * sim.model.opt.timestep) for k in range(1, steps + 1))


def run_case(case: str, settings: dict[str, Any]) -> tuple[dict[str, Any], Any, list[Any]]:
    """Simulate ``case`` under ``settings``: its figures, the model and the mocap path it took."""
    with settings_applied(settings), tempfile.TemporaryDirectory() as tmp:
        sim, targets = commands(case, Path(tmp))
        seg, dt = sim.built.seg_length, float(sim.model.opt.timestep)
        pen = squeeze = speed = 0.0
        prev, path, error = None, [], ""
        try:
            for pos, quat in targets:
                sim.set_target(pos, quat)
                rec = sim.step()
                path.append((sim.data.mocap_pos.copy(), sim.data.mocap_quat.copy()))
                if len(rec.contact_arrays):
                    pen = max(pen, -float(rec.contact_arrays.dist.min()))
                lengths = np.linalg.norm(np.diff(rec.points, axis=0), axis=1)
                squeeze = max(squeeze, float(np.abs(lengths / seg - 1.0).max()))
                if prev is not None:
                    speed = max(speed, float(np.linalg.norm(rec.points - prev, axis=1).max()) / dt)
                prev = rec.points
        except SimulationDiverged as e:
            error = str(e)
    row = {"case": case, "settings": settings, "penetration_mm": round(pen * 1000, 2),
           "squeeze": round(squeeze, 3), "speed_m_s": round(speed, 2), "steps": len(path), "diverged": error}
    return row, sim.model, path


def bare_us(model: Any, path: list[Any]) -> float:
    """Thread-CPU µs per bare ``mj_step`` along ``path`` (mocap poses) from a fresh state."""
    d = mujoco.MjData(model)
    t0 = time.thread_time()
    for pos, quat in path:
        d.mocap_pos[:], d.mocap_quat[:] = pos, quat
        mujoco.mj_step(model, d)
    return (time.thread_time() - t0) / max(len(path), 1) * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--settings", nargs="*", default=[json.dumps(BEFORE), "{}"])
    ap.add_argument("--cases", nargs="*", default=list(CASES))
    ap.add_argument("--timing", default=None, help="also time bare mj_step on this case")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    settings = [json.loads(s) for s in a.settings]
    for case in a.cases:
        for s in settings:
            print(json.dumps(run_case(case, s)[0]), flush=True)
    if a.timing:
        runs = [run_case(a.timing, s) for s in settings]
        times: list[list[float]] = [[] for _ in runs]
        for _ in range(a.repeat):
            for i, (_, model, path) in enumerate(runs):
                times[i].append(bare_us(model, path))
        for s, t, (row, _, _) in zip(settings, times, runs, strict=True):
            print(f"{a.timing} {json.dumps(s)}: bare mj_step {statistics.median(t):.0f} µs/step "
                  f"over {row['steps']} steps (rounds: {', '.join(f'{x:.0f}' for x in t)})")


if __name__ == "__main__":
    main()
