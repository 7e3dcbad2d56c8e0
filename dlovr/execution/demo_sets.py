"""Sets of perturbed demonstrations (``dlovr record --script S --trials N --seed S --vary ... -o DIR``):
one scripted demonstration recorded in N scenes perturbed like the robustness trials'
(:mod:`dlovr.execution.variation`, same ``--vary`` syntax and draws), for ``dlovr network DIR``.

Demonstration ``k`` of seed ``s`` is ``DIR/demo_KKK.mcap``: the script played from the perturbed
scene's gripper pose, the perturbed scene embedded (so it replays and verifies), and in its metadata
the trial, the seed, the drawn values and ``base_scene_sha256``, the hash of the unperturbed scene,
by which ``dlovr network`` merges perturbed recordings of one scene. ``DIR/demos.json`` lists them.
A demonstration whose simulation diverged is kept up to there and reported; one whose perturbed
scene cannot start (the cable inside an obstacle) writes no file and is reported.

With ``--vary demo.*`` keys the script is played by the person-like demonstrator
(:mod:`dlovr.recording.person`, docs/people.md), its hand drawn from the seed and the trial; the
recording's metadata names the demonstrator (``demonstrator``: its motion's fields as JSON).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dlovr.execution.recorded import scene_bundle
from dlovr.execution.variation import Variation, perturb


@dataclass(frozen=True)
class DemoSetup:
    """What each perturbed demonstration needs (picklable): the scene, its convex pieces (object
    frames: valid for every perturbation), the script, the variations, the seed, the output folder
    (absolute) and the unperturbed scene's hash; ``force``: existing demonstrations and ``demos.json``
    are replaced (else refused: nothing recorded is overwritten)."""

    scene: Any
    pieces: Any
    script: Any
    variations: tuple[Variation, ...]
    seed: int
    out_dir: str
    base_sha256: str
    force: bool = False


def demo_path(setup: DemoSetup, trial: int) -> Path:
    return Path(setup.out_dir) / f"demo_{trial:03d}.mcap"


def record_demo(setup: DemoSetup, trial: int) -> dict[str, Any]:
    """Record demonstration ``trial`` (see the module docstring); a JSON-able summary of it."""
    from dlovr.execution.run import fresh_simulator
    from dlovr.recording import DemoRecorder
    from dlovr.recording.person import PersonScript, motion_of
    from dlovr.recording.scripted import play_script

    scene, values = perturb(setup.scene, setup.variations, setup.seed, trial)
    motion = motion_of(values)
    script = setup.script if motion is None else PersonScript(setup.script, motion, setup.seed, trial)
    out: dict[str, Any] = {"trial": trial, "seed": setup.seed, "values": values, "path": None}
    sim, why = fresh_simulator(scene, setup.pieces)
    if sim is None:
        return {**out, "error": str(why), "situations": 0}
    path = demo_path(setup, trial)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        "source": "dlovr record --trials",
        "trial": str(trial),
        "seed": str(setup.seed),
        "vary": json.dumps(values),
        "base_scene_sha256": setup.base_sha256,
    }
    if motion is not None:
        meta["demonstrator"] = json.dumps(dataclasses.asdict(motion))
    bundle = scene_bundle(scene)
    with DemoRecorder(
        path, scene, sim, sim.tracker, bundle=bundle, extra_metadata=meta, overwrite=setup.force
    ) as rec:
        error = play_script(sim, script, rec)
    return {**out, "path": path.name, "error": error, "situations": len(sim.tracker.kept)}


def record_demos(
    setup: DemoSetup, n: int, *, workers: int = 1, cluster: str | None = None, progress: bool = False
) -> list[dict[str, Any]]:
    """Demonstrations ``0..n-1`` through :func:`dlovr.batch.run_batch` (this process, ``workers``
    local processes, or Ray with ``cluster``); summaries in trial order. A task that gave no result
    (it raised, or its worker died on every attempt) is reported with its error."""
    from dlovr.batch import Task, run_batch

    tasks = [Task(f"demo {k}", (setup, k)) for k in range(n)]
    done: dict[int, dict[str, Any]] = {}
    for r in run_batch(record_demo, tasks, workers=workers, cluster=cluster, progress=progress,
                       label=f"{n} demonstrations"):
        if r.ok:
            done[r.index] = {**r.value, "attempts": r.attempts}
        else:
            done[r.index] = {"trial": r.index, "seed": setup.seed, "path": None, "error": str(r.error),
                             "situations": 0, "attempts": r.attempts}
    return [done[k] for k in range(n)]


def write_index(setup: DemoSetup, demos: Sequence[dict[str, Any]]) -> Path:
    """``DIR/demos.json``: the scene, the seed, the variations and each demonstration's summary;
    written atomically, an existing one replaced only with ``setup.force``
    (:func:`dlovr.outputs.write_output`)."""
    from dlovr.outputs import write_output

    index = {
        "scene": setup.scene.name,
        "base_scene_sha256": setup.base_sha256,
        "script": getattr(setup.script, "source", ""),
        "seed": setup.seed,
        "vary": [f"{v.key}={v.spec}" for v in setup.variations],
        "demonstrations": list(demos),
    }
    path = Path(setup.out_dir) / "demos.json"
    write_output(path, json.dumps(index, indent=1) + "\n", force=setup.force)
    return path
