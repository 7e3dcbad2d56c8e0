"""Recordings as demonstrations of a transition network (``dlovr network``): the kept contact
situations and the gripper pose track of each, read from the contact-state channel only."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np

from dlovr.model.network import Demonstration, Network, NetworkError, build_network
from dlovr.model.program import ChatterRules, PoseTrack
from dlovr.recording.format import RecordingError, one_line
from dlovr.recording.reader import Recording, kept_states


def demonstration(path: str | Path, hold: float | None = None) -> Demonstration:
    """One recording as a :class:`~dlovr.model.network.Demonstration` (scene name and hash from its
    metadata: for a demonstration in a perturbed scene (``dlovr record --trials``) the hash of the
    unperturbed scene, ``base_scene_sha256``, so that perturbed runs of one scene merge; gripper poses
    from its contact-state messages, world frame, m and wxyz; the sensed wrench when it has one; the
    commanded gripper track, for the edges' own tracks; whether it is a recorded program run, metadata
    ``source`` ``dlovr run``)."""
    rec = Recording(path)
    states = kept_states(rec, hold)
    payloads = rec.states()
    try:
        t = np.array([float(p["t"]) for p in payloads])
        pos = np.array([p.get("gripper_pos", [0.0, 0.0, 0.0]) for p in payloads], dtype=float)
        quat = np.array([p.get("gripper_quat", [1.0, 0.0, 0.0, 0.0]) for p in payloads], dtype=float)
        poses = PoseTrack(t, pos, quat)
    except (KeyError, TypeError, ValueError) as e:
        raise RecordingError(f"{rec.path}: bad gripper pose in the contact states: {one_line(e)}") from None
    steps, cpos, cquat = rec.commands()
    commands = PoseTrack(steps * rec.dt, cpos, cquat)
    return Demonstration(
        str(rec.path),
        tuple(states),
        poses,
        rec.metadata.get("scene_name", ""),
        rec.metadata.get("base_scene_sha256") or rec.metadata.get("scene_sha256", ""),
        rec.wrench(),
        commands,
        rec.metadata.get("source") == "dlovr run",
    )


def network_from_recordings(
    paths: Sequence[str | Path],
    hold: float | None = None,
    progress: Callable[[int], None] | None = None,
    *,
    workers: int | None = None,
    cluster: str | None = None,
    chatter: ChatterRules | None = None,
    hands_only: bool = False,
) -> Network:
    """Build a transition network from recordings of one scene; ``progress(k)`` after each one read
    (with ``workers`` / ``cluster``: as the k-th completes, in order of completion); ``chatter``: each
    recording's chatter removed first (with ``hands_only``: of each recording a hand made;
    :func:`dlovr.model.network.build_network`).

    The recordings are read here one after the other, or with ``workers`` / ``cluster`` through
    :func:`dlovr.batch.run_batch` (local processes or Ray; the network is the same, it is built from
    the demonstrations in input order). Raises :class:`RecordingError` for an unreadable recording
    and :class:`~dlovr.model.network.NetworkError` for recordings of different scenes (read one after
    the other: checked as soon as the second scene is read, before the rest are).
    """
    demos: list[Demonstration] = []
    batched = workers is not None or cluster is not None
    read = _demonstrations(paths, hold, workers, cluster, progress if batched else None)
    for k, d in enumerate(read, 1):
        if demos and (d.scene_sha256, d.scene_name) != (demos[0].scene_sha256, demos[0].scene_name):
            f = demos[0]
            raise NetworkError(
                f"{d.name}: scene {d.scene_name} ({d.scene_sha256[:12]}) differs from {f.name}'s scene "
                f"{f.scene_name} ({f.scene_sha256[:12]}); a network merges recordings of one scene"
            )
        demos.append(d)
        if progress is not None and not batched:
            progress(k)
    return build_network(demos, chatter, hands_only=hands_only)


def _demonstrations(
    paths: Sequence[str | Path],
    hold: float | None,
    workers: int | None,
    cluster: str | None,
    progress: Callable[[int], None] | None = None,
) -> Iterator[Demonstration]:
    """The recordings as demonstrations, in input order; read through the batch engine (``workers`` or
    ``cluster``), ``progress(k)`` as the k-th one completes, in order of completion."""
    if workers is None and cluster is None:
        yield from (demonstration(p, hold) for p in paths)
        return
    from dlovr.batch import Task, run_batch

    tasks = [Task(f"{i}:{p}", (str(p), hold)) for i, p in enumerate(paths)]
    done = []
    for r in run_batch(demonstration, tasks, workers=workers, cluster=cluster, progress=False):
        done.append(r)
        if progress is not None:
            progress(len(done))
    done.sort(key=lambda r: r.index)
    for r in done:
        if not r.ok:
            raise RecordingError(str(r.error))
        yield r.value
