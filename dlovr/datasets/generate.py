"""Generated datasets (``dlovr generate``): a program run in perturbed scenes as robustness trials
(:func:`dlovr.execution.trials.run_trials`, the same draws as ``dlovr run --trials``), each run
recorded; the runs that reached the goal re-simulated into episodes and written as one dataset.
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from dlovr.datasets import (
    DatasetError,
    Episode,
    ExportOptions,
    check_output,
    gather_episode,
    write_dataset,
)


@dataclass(frozen=True)
class GenerateResult:
    """``trials``: every trial's result (as ``dlovr run --trials`` writes them); ``kept``: the trials
    that reached the goal, in order (the dataset's episodes); ``failures``: why the others failed
    (reason -> count)."""

    trials: list[dict[str, Any]]
    kept: list[int]
    failures: dict[str, int]


def trial_setup(
    program_path: str, varies: Sequence[str], seed: int, *, detect: str = "force", noise: float = 0.0,
    path_mode: str = "auto", note: Callable[[str], None] | None = None,
) -> Any:
    """The :class:`dlovr.execution.trials.TrialSetup` that ``dlovr run PROGRAM --trials`` makes from
    the same options (a compiled or a network program; ``path_mode``: auto, demo or program).
    ``note`` is told when the macros cannot follow the demonstration (its recording not found), as
    ``dlovr run`` says it: another way of moving, another result."""
    from dlovr.execution.demo_track import load_track
    from dlovr.execution.executor import ExecOptions
    from dlovr.execution.network_run import network_scene
    from dlovr.execution.run import POSES_INSTEAD, find_recording, not_found, resolve_scene
    from dlovr.execution.trials import TrialSetup
    from dlovr.execution.variation import parse_varies
    from dlovr.geometry import scene_pieces
    from dlovr.model.planning import NetworkProgram, load_runnable

    program = load_runnable(program_path)
    opts = ExecOptions(detect=detect, noise=noise)
    track = None
    if isinstance(program, NetworkProgram):
        if path_mode == "demo":
            raise DatasetError(f"{program_path}: a network program has no single demonstration to follow")
        scene = network_scene(program, None)
    else:
        rec = find_recording(program)
        scene = resolve_scene(program, None, rec)
        if rec is None and path_mode == "demo":
            raise DatasetError(f"{program_path}: {not_found(program)}")
        if rec is None and path_mode == "auto" and note is not None:
            note(f"{program_path}: {not_found(program)}, so {POSES_INSTEAD}")
        track = load_track(rec) if rec is not None and path_mode != "program" else None
    return TrialSetup(
        program=program, scene=scene, pieces=scene_pieces(scene), track=track,
        variations=parse_varies(varies, scene), seed=seed, opts=opts, use_track=track is not None,
    )


def generate(
    setup: Any, episodes: int, out: str | Path, opts: ExportOptions, *, workers: int = 1,
    cluster: str | None = None, progress: bool = False,
) -> GenerateResult:
    """Run ``episodes`` trials of ``setup`` on ``workers`` processes, or on Ray (``cluster``: ``local``,
    ``auto`` or an address; ``workers`` then caps the tasks in flight), record them in a temporary
    folder and write those that reached the goal to ``out`` (``opts``: format, fps, cameras). The
    result is the same wherever the trials ran. On a cluster the trials and their re-simulation run
    on its workers, through one connection, and the temporary folder is made beside ``out`` (storage
    every node must see)."""
    from dlovr.batch import cluster_session
    from dlovr.execution.trials import run_trials

    dest = check_output(out, opts.fmt, opts.force)
    where = str(dest.resolve().parent) if cluster is not None else None
    with cluster_session(cluster, workers if cluster is not None else None), \
            tempfile.TemporaryDirectory(prefix=".dlovr-generate-", dir=where) as tmp:
        trials = run_trials(replace(setup, record_dir=tmp), episodes, workers=workers, cluster=cluster,
                            progress=progress)
        kept = [t["trial"] for t in trials if t["program"]["success"]]
        paths = [str(Path(tmp) / f"trial_{k:03d}.mcap") for k in kept]
        if paths:
            eps = iter_episodes(paths, opts, workers=workers, cluster=cluster, progress=progress)
            write_dataset(eps, out, opts.fmt)
    failures: dict[str, int] = {}
    for t in trials:
        p = t["program"]
        if not p["success"]:
            key = f"macro {p['failed_macro']}: {p['reason']}" if p.get("failed_macro") else p["reason"]
            failures[key] = failures.get(key, 0) + 1
    return GenerateResult(trials, kept, failures)


def iter_episodes(
    paths: Sequence[str], opts: ExportOptions, *, workers: int = 1, cluster: str | None = None,
    progress: bool = False,
) -> Iterator[Episode]:
    """:func:`dlovr.datasets.frames.gather_episode` of each recording, in order: on ``workers``
    processes, or on Ray (``cluster``, as :func:`dlovr.batch.run_batch`)."""
    from dlovr.batch import Task, run_batch

    if cluster is None and (workers <= 1 or len(paths) <= 1):
        for p in paths:
            yield gather_episode(p, opts.fps, opts.cameras, opts.size)
        return
    tasks = [Task(p, (p, opts.fps, opts.cameras, opts.size)) for p in paths]
    waiting: dict[int, Episode] = {}
    nxt = 0
    batch = run_batch(gather_episode, tasks, workers=workers, cluster=cluster, progress=progress,
                      label="episodes")
    for r in batch:
        if not r.ok:
            raise DatasetError(f"{r.key}: cannot re-simulate: {r.error}")
        waiting[r.index] = r.value
        while nxt in waiting:
            yield waiting.pop(nxt)
            nxt += 1
