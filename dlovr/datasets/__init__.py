"""Demonstrations as learning datasets (docs/datasets.md): recordings re-simulated into frames of
state, action and labels (:mod:`~dlovr.datasets.frames`), optionally with camera videos
(:mod:`~dlovr.datasets.cameras`), written as LeRobot v3.0 (:mod:`~dlovr.datasets.lerobot`) or robomimic
HDF5 (:mod:`~dlovr.datasets.robomimic`); :mod:`~dlovr.datasets.generate` makes them from a program run in
perturbed scenes.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from dlovr.datasets.frames import CABLE_NODES, LABELS, Episode, gather_episode
from dlovr.inputs import InputError

FORMATS = ("lerobot", "robomimic")


class DatasetError(InputError):
    """Bad export or generate input (one line)."""


@dataclass(frozen=True)
class ExportOptions:
    """``fmt``: one of :data:`FORMATS`; ``fps``: frames per second; ``cameras``: names to render at
    ``size`` (width, height) pixels; ``force``: replace an existing dataset at the output."""

    fmt: str = "lerobot"
    fps: float = 30.0
    cameras: tuple[str, ...] = ()
    size: tuple[int, int] = (320, 240)
    force: bool = False


def check_output(out: str | Path, fmt: str, force: bool) -> Path:
    """The output path, checked: nothing there, or (``force``) a dataset of ``fmt`` to replace."""
    p = Path(out)
    if fmt == "robomimic" and p.suffix not in (".hdf5", ".h5"):
        raise DatasetError(f"{p}: a robomimic dataset is one .hdf5 file")
    if not p.exists() and not p.is_symlink():
        if not p.parent.is_dir():
            raise DatasetError(f"{p}: its folder {p.parent} does not exist")
        return p
    if not force:
        raise DatasetError(f"{p}: exists (give --force to replace it)")
    ours = (p / "meta" / "info.json").is_file() if fmt == "lerobot" else p.is_file()
    if not ours:
        raise DatasetError(f"{p}: exists and is not a {fmt} dataset: not replaced")
    return p


def write_dataset(episodes: Iterable[Episode], out: str | Path, fmt: str, task: str | None = None) -> Path:
    """Write ``episodes`` in ``fmt`` to ``out``, one at a time as they come (their images are encoded
    and dropped), through a temporary sibling that replaces what is at ``out`` only once the new
    dataset is complete. ``task``: the dataset's task text (default: from the first episode's scene)."""
    from dlovr.datasets.lerobot import LeRobotWriter
    from dlovr.datasets.robomimic import RobomimicWriter

    p = Path(out)
    tmp = Path(tempfile.mkdtemp(prefix=f".{p.name}.", dir=p.parent))
    writer: LeRobotWriter | RobomimicWriter | None = None
    try:
        staged = tmp / p.name
        names: tuple[str, ...] | None = None
        for ep in episodes:
            if writer is None:
                cls = LeRobotWriter if fmt == "lerobot" else RobomimicWriter
                writer, names = cls(staged, task or task_of(ep)), ep.object_names
            elif ep.object_names != names:
                why = "its scene's objects differ from the first episode's: export them separately"
                raise DatasetError(f"{ep.info['source']}: {why}")
            writer.add(ep)
        if writer is None:
            raise DatasetError(f"{out}: no episodes to write")
        writer.close()
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        staged.replace(p)
    finally:
        if writer is not None:
            writer.abort()
        shutil.rmtree(tmp, ignore_errors=True)
    return p


def export(recordings: Sequence[str | Path], out: str | Path, opts: ExportOptions) -> list[Episode]:
    """Re-simulate ``recordings`` (one episode each, in order) and write them to ``out``; the episodes
    written, without their images."""
    check_output(out, opts.fmt, opts.force)
    done: list[Episode] = []

    def episodes() -> Iterator[Episode]:
        for r in recordings:
            ep = gather_episode(r, opts.fps, opts.cameras, opts.size)
            done.append(replace(ep, images={}))
            yield ep

    write_dataset(episodes(), out, opts.fmt)
    return done


def task_of(ep: Episode) -> str:
    """A dataset's task text: the first episode's scene."""
    import tomllib

    return "cable manipulation in " + str(tomllib.loads(ep.info["scene_toml"]).get("name", "a scene"))


__all__ = [
    "CABLE_NODES", "FORMATS", "LABELS", "DatasetError", "Episode", "ExportOptions", "check_output", "export",
    "gather_episode", "write_dataset",
]
