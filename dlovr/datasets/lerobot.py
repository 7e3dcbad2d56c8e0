"""Episodes written as a LeRobot v3.0 dataset with pyarrow and PyAV (docs/datasets.md):

``meta/info.json`` (features, fps, paths), ``meta/stats.json``, ``meta/tasks.parquet``,
``meta/episodes/chunk-000/file-000.parquet`` (one row per episode: its frames' and videos' places,
and dlovr's per-episode facts under ``dlovr/``), ``meta/labels.json`` (the label vocabularies),
``data/chunk-000/file-000.parquet`` (one row per frame) and, per camera,
``videos/observation.images.<camera>/chunk-000/file-000.mp4`` (H.264, yuv420p; the episodes one after
the other, each from its ``from_timestamp``).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from dlovr.datasets.frames import CABLE_NODES, LABELS, Episode

CODEBASE_VERSION = "v3.0"
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
EPISODES_PATH = "meta/episodes/chunk-000/file-000.parquet"
VIDEO_CODEC = "h264"


def state_names(objects: Sequence[str]) -> list[str]:
    """The names of ``observation.state``'s entries: gripper pose, wrench, cable nodes, object poses."""
    names = [f"gripper.{a}" for a in ("x", "y", "z", "qw", "qx", "qy", "qz")]
    names += [f"wrench.{a}" for a in ("fx", "fy", "fz", "tx", "ty", "tz")]
    names += [f"cable.{i}.{a}" for i in range(CABLE_NODES) for a in "xyz"]
    names += [f"{o}.{a}" for o in objects for a in ("x", "y", "z", "qw", "qx", "qy", "qz")]
    return names


def state_vector(ep: Episode) -> np.ndarray:
    """``observation.state`` of every frame, float64 (n, 13 + 3 CABLE_NODES + 7 K)."""
    n = ep.length
    parts = [ep.gripper_pos, ep.gripper_quat, ep.wrench, ep.cable.reshape(n, -1), ep.objects.reshape(n, -1)]
    return np.concatenate(parts, axis=1)


class LeRobotWriter:
    """Writes a LeRobot v3.0 dataset into the new folder ``out`` one episode at a time: the camera
    images are encoded as each episode comes and not kept (only every 10th frame, for the stats);
    the tables and metadata are written by :meth:`close`."""

    def __init__(self, out: str | Path, task: str):
        self.out, self.task = Path(out), task
        self.episodes: list[Episode] = []
        self.videos: dict[str, _Video] = {}
        self.samples: dict[str, list[np.ndarray]] = {}

    def add(self, ep: Episode) -> None:
        """Append episode ``ep`` (its cameras those of the first episode)."""
        from dataclasses import replace

        if not self.episodes:
            (self.out / "meta" / "episodes" / "chunk-000").mkdir(parents=True)
            (self.out / "data" / "chunk-000").mkdir(parents=True)
            self.videos = {c: _Video(self.out, c, ep.fps) for c in sorted(ep.images)}
            self.samples = {c: [] for c in self.videos}
        elif sorted(ep.images) != sorted(self.videos):
            have, first = sorted(ep.images), sorted(self.videos)
            raise ValueError(f"episode {ep.name}: cameras {have}, the first episode's {first}")
        for cam, video in self.videos.items():
            video.write(ep.images[cam])
            self.samples[cam].append(ep.images[cam][::10])
        self.episodes.append(replace(ep, images={}))

    def abort(self) -> None:
        """Close the videos without writing the metadata."""
        for v in self.videos.values():
            v.close()

    def close(self) -> Path:
        """Finish the videos and write the frame table, the episodes, tasks, info and stats."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        episodes, out, task = self.episodes, self.out, self.task
        video_info = {c: v.close() for c, v in self.videos.items()}
        cams = sorted(video_info)
        vocab = _vocabularies(episodes)
        rows, offsets = _data_columns(episodes, vocab)
        pq.write_table(pa.table(rows), out / DATA_PATH.format(chunk_index=0, file_index=0))
        pq.write_table(_episodes_table(episodes, offsets, cams, task), out / EPISODES_PATH)
        pq.write_table(_tasks_table([task]), out / "meta" / "tasks.parquet")
        fps = episodes[0].fps
        info = {
            "codebase_version": CODEBASE_VERSION, "robot_type": "dlovr_gripper",
            "total_episodes": len(episodes), "total_frames": int(offsets[-1]), "total_tasks": 1,
            "chunks_size": 1000, "data_files_size_in_mb": 100, "video_files_size_in_mb": 500, "fps": fps,
            "splits": {"train": f"0:{len(episodes)}"}, "data_path": DATA_PATH,
            "video_path": VIDEO_PATH if cams else None, "features": _features(episodes[0], video_info),
            "dlovr": {"cable_nodes": CABLE_NODES, "versions": episodes[0].info["versions"]},
        }
        _write_json(out / "meta" / "info.json", info)
        _write_json(out / "meta" / "stats.json", _stats(rows, self.samples))
        _write_json(out / "meta" / "labels.json", vocab)
        return out


def _write_json(path: Path, obj: Any) -> None:
    path.write_text(json.dumps(obj, indent=1) + "\n", encoding="utf-8")


def _vocabularies(episodes: Sequence[Episode]) -> dict[str, list[str]]:
    """Per label name the sorted distinct values; a frame's label is its index in this list."""
    return {name: sorted({v for ep in episodes for v in ep.labels[name]}) for name in LABELS}


def _data_columns(
    episodes: Sequence[Episode], vocab: dict[str, list[str]]
) -> tuple[dict[str, Any], list[int]]:
    """The frame table's columns (as pyarrow arrays) and each episode's first global index (+ the total)."""
    import pyarrow as pa

    def vectors(x: np.ndarray) -> Any:
        x = np.ascontiguousarray(x, np.float32)
        return pa.FixedSizeListArray.from_arrays(pa.array(x.ravel()), x.shape[1])

    offsets = [0]
    for ep in episodes:
        offsets.append(offsets[-1] + ep.length)
    cat = np.concatenate
    cols: dict[str, Any] = {
        "observation.state": vectors(cat([state_vector(ep) for ep in episodes])),
        "action": vectors(cat([ep.action for ep in episodes])),
        "action.delta": vectors(cat([ep.action_delta for ep in episodes])),
        "observation.sim_time": pa.array(cat([ep.sim_time for ep in episodes])),
    }
    for name in LABELS:
        index = {v: i for i, v in enumerate(vocab[name])}
        cols[f"label.{name}"] = pa.array([index[v] for ep in episodes for v in ep.labels[name]], pa.int64())
    cols["label.macro_index"] = pa.array(cat([ep.macro_index for ep in episodes]), pa.int64())
    cols["timestamp"] = pa.array(cat([ep.timestamps for ep in episodes]).astype(np.float32))
    cols["frame_index"] = pa.array(cat([np.arange(ep.length) for ep in episodes]), pa.int64())
    which = cat([np.full(ep.length, i) for i, ep in enumerate(episodes)])
    cols["episode_index"] = pa.array(which, pa.int64())
    cols["index"] = pa.array(np.arange(offsets[-1]), pa.int64())
    cols["task_index"] = pa.array(np.zeros(offsets[-1], np.int64))
    return cols, offsets


def _features(ep: Episode, video_info: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """info.json's ``features``: dtype, shape and names of every column and video."""
    n_state = len(state_names(ep.object_names))
    f: dict[str, Any] = {
        "observation.state": {"dtype": "float32", "shape": [n_state], "names": state_names(ep.object_names)},
        "action": {"dtype": "float32", "shape": [7], "names": ["x", "y", "z", "qw", "qx", "qy", "qz"]},
        "action.delta": {"dtype": "float32", "shape": [6], "names": ["dx", "dy", "dz", "rx", "ry", "rz"]},
        "observation.sim_time": {"dtype": "float64", "shape": [1], "names": None},
    }
    for name in (*LABELS, "macro_index"):
        f[f"label.{name}"] = {"dtype": "int64", "shape": [1], "names": None}
    for cam, info in video_info.items():
        f[f"observation.images.{cam}"] = {
            "dtype": "video", "shape": [info["video.height"], info["video.width"], 3],
            "names": ["height", "width", "channels"], "info": info,
        }
    for name, dtype in (("timestamp", "float32"), ("frame_index", "int64"), ("episode_index", "int64"),
                        ("index", "int64"), ("task_index", "int64")):
        f[name] = {"dtype": dtype, "shape": [1], "names": None}
    return f


class _Video:
    """One camera's MP4 (H.264, yuv420p): the episodes' frames one after the other."""

    def __init__(self, out: Path, cam: str, fps: float):
        import av

        key = f"observation.images.{cam}"
        self.path = out / VIDEO_PATH.format(video_key=key, chunk_index=0, file_index=0)
        self.path.parent.mkdir(parents=True)
        self.fps, self.rate = fps, Fraction(fps).limit_denominator(1000)
        self.container: Any = av.open(str(self.path), "w")
        self.stream: Any = None
        self.frames = 0

    def write(self, images: np.ndarray) -> None:
        """Encode ``images`` (n, H, W, 3) uint8."""
        import av

        if self.stream is None:
            h, w = images.shape[1:3]
            options = {"g": "2", "crf": "23"}  # a key frame every 2 frames: quick seeks, as LeRobot's
            self.stream = self.container.add_stream("libx264", rate=self.rate, options=options)
            self.stream.width, self.stream.height, self.stream.pix_fmt = w, h, "yuv420p"
            self.stream.time_base = 1 / self.rate
        for img in images:
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(img), format="rgb24")
            frame.pts = self.frames
            self.frames += 1
            self.container.mux(self.stream.encode(frame))

    def close(self) -> dict[str, Any]:
        """Flush and close the file; its video info (for info.json)."""
        if self.container is None:
            return {}
        if self.stream is not None:
            self.container.mux(self.stream.encode())
        self.container.close()
        self.container = None
        h, w = (self.stream.height, self.stream.width) if self.stream is not None else (0, 0)
        return {"video.height": int(h), "video.width": int(w), "video.codec": VIDEO_CODEC,
                "video.pix_fmt": "yuv420p", "video.is_depth_map": False, "video.fps": self.fps,
                "video.channels": 3, "has_audio": False}


def _episodes_table(episodes: Sequence[Episode], offsets: list[int], cams: Sequence[str], task: str) -> Any:
    """meta/episodes: one row per episode (LeRobot's columns, then dlovr's facts under ``dlovr/``)."""
    import pyarrow as pa

    n = len(episodes)
    zeros = [0] * n
    cols: dict[str, Any] = {
        "episode_index": list(range(n)), "tasks": [[task] for _ in episodes],
        "length": [ep.length for ep in episodes],
        "data/chunk_index": zeros, "data/file_index": zeros,
        "dataset_from_index": offsets[:-1], "dataset_to_index": offsets[1:],
    }
    for cam in cams:
        key = f"videos/observation.images.{cam}"
        start = [offsets[i] / episodes[0].fps for i in range(n)]
        cols[f"{key}/chunk_index"], cols[f"{key}/file_index"] = zeros, zeros
        cols[f"{key}/from_timestamp"] = start
        cols[f"{key}/to_timestamp"] = [s + ep.length / ep.fps for s, ep in zip(start, episodes, strict=True)]
    cols["meta/episodes/chunk_index"], cols["meta/episodes/file_index"] = zeros, zeros
    info_keys = ("source", "kind", "success", "scene_toml", "scene_sha256", "mjcf", "seed", "trial")
    for key in info_keys:
        cols[f"dlovr/{key}"] = [ep.info[key] for ep in episodes]
    cols["dlovr/vary"] = [json.dumps(ep.info["vary"]) for ep in episodes]
    cols["dlovr/versions"] = [json.dumps(ep.info["versions"]) for ep in episodes]
    return pa.table(cols)


def _tasks_table(tasks: Sequence[str]) -> Any:
    """meta/tasks.parquet: ``task_index`` indexed by the task's text (pandas' index metadata, as
    LeRobot reads it with pandas)."""
    import pyarrow as pa

    meta = {
        "index_columns": ["task"],
        "column_indexes": [{"name": None, "field_name": None, "pandas_type": "unicode",
                            "numpy_type": "object", "metadata": {"encoding": "UTF-8"}}],
        "columns": [
            {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64",
             "metadata": None},
            {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object",
             "metadata": None},
        ],
        "creator": {"library": "pyarrow", "version": pa.__version__}, "pandas_version": "2.2.0",
    }
    table = pa.table({"task_index": pa.array(range(len(tasks)), pa.int64()), "task": list(tasks)})
    return table.replace_schema_metadata({"pandas": json.dumps(meta)})


def _stats(rows: dict[str, Any], samples: dict[str, list[np.ndarray]]) -> dict[str, Any]:
    """meta/stats.json: min, max, mean, std and count of every numeric column and (per channel, in
    0..1, over every 10th frame) of every camera."""
    out: dict[str, Any] = {}
    for key, col in rows.items():
        x = np.asarray(col.flatten() if hasattr(col, "flatten") else col, float)
        x = x.reshape(len(col), -1).astype(np.float64)
        out[key] = {"min": x.min(0).tolist(), "max": x.max(0).tolist(), "mean": x.mean(0).tolist(),
                    "std": x.std(0).tolist(), "count": [len(x)]}
    for cam, parts in samples.items():
        sample = np.concatenate(parts)
        px = sample.reshape(-1, 3) / 255.0
        out[f"observation.images.{cam}"] = {
            k: np.asarray(v).reshape(3, 1, 1).tolist()
            for k, v in (("min", px.min(0)), ("max", px.max(0)), ("mean", px.mean(0)), ("std", px.std(0)))
        } | {"count": [len(sample)]}
    return out
