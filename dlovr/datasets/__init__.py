"""Demonstrations as learning datasets (docs/datasets.md): recordings re-simulated into frames of
state, action and labels (:mod:`~dlovr.datasets.frames`), optionally with camera videos
(:mod:`~dlovr.datasets.cameras`), written as LeRobot v3.0 (:mod:`~dlovr.datasets.lerobot`) or robomimic
HDF5 (:mod:`~dlovr.datasets.robomimic`); :mod:`~dlovr.datasets.generate` makes them from a program run in
perturbed scenes.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
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


def write_dataset(episodes: Sequence[Episode], out: str | Path, fmt: str, task: str) -> Path:
    """Write ``episodes`` in ``fmt`` to ``out`` through a temporary sibling, replacing what is there
    only once the new dataset is complete."""
    from dlovr.datasets.lerobot import write_lerobot
    from dlovr.datasets.robomimic import write_robomimic

    if not episodes:
        raise DatasetError(f"{out}: no episodes to write")
    if len({ep.object_names for ep in episodes}) > 1:
        raise DatasetError(f"{out}: the episodes' scenes have different objects: export them separately")
    p = Path(out)
    tmp = Path(tempfile.mkdtemp(prefix=f".{p.name}.", dir=p.parent))
    try:
        staged = tmp / p.name
        (write_lerobot if fmt == "lerobot" else write_robomimic)(episodes, staged, task)
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        staged.replace(p)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return p


def export(recordings: Sequence[str | Path], out: str | Path, opts: ExportOptions) -> list[Episode]:
    """Re-simulate ``recordings`` (one episode each, in order) and write them to ``out``."""
    check_output(out, opts.fmt, opts.force)
    episodes = [gather_episode(r, opts.fps, opts.cameras, opts.size) for r in recordings]
    write_dataset(episodes, out, opts.fmt, task=task_of(episodes))
    return episodes


def task_of(episodes: Sequence[Episode]) -> str:
    """The dataset's task text: the scenes of its episodes."""
    import tomllib

    names = sorted({tomllib.loads(ep.info["scene_toml"]).get("name", "scene") for ep in episodes})
    return "cable manipulation in " + ", ".join(names)


__all__ = [
    "CABLE_NODES", "FORMATS", "LABELS", "DatasetError", "Episode", "ExportOptions", "check_output", "export",
    "gather_episode", "write_dataset",
]
