"""Episodes written as a robomimic HDF5 file with h5py (docs/datasets.md).

``data`` (attributes ``total``: frames, ``env_args``: JSON, ``fps``, ``cable_nodes``, ``versions``)
holds one group ``demo_<i>`` per episode: ``states`` (MuJoCo's ``mjSTATE_INTEGRATION``, float64),
``actions`` (the commanded gripper pose, 7), ``action_dict/{abs_pos, abs_quat, delta_pos,
delta_rot}``, ``rewards`` (1 at the last frame of a successful episode), ``dones`` (1 at the last
frame), ``obs/{gripper_pos, gripper_quat, gripper_wrench, cable, object_poses, sim_time,
<camera>_image}``, ``labels/{situation, principal, stability, transition, macro_class,
macro_index}``; its attributes ``num_samples``, ``model_file`` (MJCF), ``scene_toml`` and the other
per-episode facts. Every float is float64, exactly the replayed simulation's values.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from dlovr.datasets.frames import CABLE_NODES, LABELS, Episode


class RobomimicWriter:
    """Writes the new HDF5 file ``out`` one episode (``demo_<i>``) at a time."""

    def __init__(self, out: str | Path, task: str):
        import h5py

        self.out, self.task = Path(out), task
        self.file: Any = h5py.File(self.out, "w-")
        self.names: list[str] = []
        self.frames = 0
        self.first: Episode | None = None

    def add(self, ep: Episode) -> None:
        """Append episode ``ep`` as ``data/demo_<i>``."""
        self.first = self.first or ep
        name = f"demo_{len(self.names)}"
        _write_demo(self.file.require_group("data").create_group(name), ep)
        self.names.append(name)
        self.frames += ep.length

    def abort(self) -> None:
        """Close the file as it is."""
        if self.file is not None:
            self.file.close()
            self.file = None

    def close(self) -> Path:
        """Write the dataset's attributes and the train mask; close the file."""
        first = self.first
        assert first is not None and self.file is not None
        data = self.file["data"]
        data.attrs["total"] = self.frames
        env = {"env_name": "dlovr", "type": 1000,
               "env_kwargs": {"task": self.task, "fps": first.fps, "cable_nodes": CABLE_NODES}}
        data.attrs["env_args"] = json.dumps(env)
        data.attrs["fps"] = first.fps
        data.attrs["cable_nodes"] = CABLE_NODES
        data.attrs["versions"] = json.dumps(first.info["versions"])
        self.file.create_group("mask").create_dataset("train", data=np.array(self.names, dtype="S"))
        self.abort()
        return self.out


def _write_demo(g: object, ep: Episode) -> None:
    """One episode's group (see the module docstring)."""
    import h5py

    assert isinstance(g, h5py.Group)
    n = ep.length
    g.attrs["num_samples"] = n
    g.attrs["model_file"] = ep.info["mjcf"]
    for key in ("source", "kind", "success", "scene_toml", "scene_sha256"):
        g.attrs[key] = ep.info[key]
    g.attrs["seed"] = -1 if ep.info["seed"] is None else ep.info["seed"]
    g.attrs["trial"] = -1 if ep.info["trial"] is None else ep.info["trial"]
    g.attrs["vary"] = json.dumps(ep.info["vary"])
    g.attrs["object_names"] = json.dumps(list(ep.object_names))
    g.create_dataset("states", data=ep.state)
    g.create_dataset("actions", data=ep.action)
    ad = g.create_group("action_dict")
    for key, x in (("abs_pos", ep.action[:, :3]), ("abs_quat", ep.action[:, 3:]),
                   ("delta_pos", ep.action_delta[:, :3]), ("delta_rot", ep.action_delta[:, 3:])):
        ad.create_dataset(key, data=x)
    rewards = np.zeros(n)
    rewards[-1] = 1.0 if ep.info["success"] else 0.0
    dones = np.zeros(n, np.int64)
    dones[-1] = 1
    g.create_dataset("rewards", data=rewards)
    g.create_dataset("dones", data=dones)
    obs = g.create_group("obs")
    for key, x in (("gripper_pos", ep.gripper_pos), ("gripper_quat", ep.gripper_quat),
                   ("gripper_wrench", ep.wrench), ("cable", ep.cable), ("object_poses", ep.objects),
                   ("sim_time", ep.sim_time)):
        obs.create_dataset(key, data=x)
    for cam, imgs in ep.images.items():
        obs.create_dataset(f"{cam}_image", data=imgs, compression="gzip")
    labels = g.create_group("labels")
    text = h5py.string_dtype("utf-8")
    for name in LABELS:
        labels.create_dataset(name, data=np.array(ep.labels[name], dtype=object), dtype=text)
    labels.create_dataset("macro_index", data=ep.macro_index)
