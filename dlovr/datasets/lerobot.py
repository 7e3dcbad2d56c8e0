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


def write_lerobot(episodes: Sequence[Episode], out: str | Path, task: str) -> Path:
    """Write ``episodes`` (one fps, one scene layout) as a LeRobot v3.0 dataset in the new folder ``out``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    out = Path(out)
    fps = episodes[0].fps
    cams = sorted(episodes[0].images)
    vocab = _vocabularies(episodes)
    rows, offsets = _data_columns(episodes, vocab)
    (out / "meta" / "episodes" / "chunk-000").mkdir(parents=True)
    (out / "data" / "chunk-000").mkdir(parents=True)
    pq.write_table(pa.table(rows), out / DATA_PATH.format(chunk_index=0, file_index=0))
    video_info = {c: _write_video(episodes, c, out, fps) for c in cams}
    pq.write_table(_episodes_table(episodes, offsets, cams, task), out / EPISODES_PATH)
    pq.write_table(_tasks_table([task]), out / "meta" / "tasks.parquet")
    features = _features(episodes[0], video_info)
    info = {
        "codebase_version": CODEBASE_VERSION, "robot_type": "dlovr_gripper",
        "total_episodes": len(episodes), "total_frames": int(offsets[-1]), "total_tasks": 1,
        "chunks_size": 1000, "data_files_size_in_mb": 100, "video_files_size_in_mb": 500, "fps": fps,
        "splits": {"train": f"0:{len(episodes)}"}, "data_path": DATA_PATH,
        "video_path": VIDEO_PATH if cams else None, "features": features,
        "dlovr": {"cable_nodes": CABLE_NODES, "versions": episodes[0].info["versions"]},
    }
    _write_json(out / "meta" / "info.json", info)
    _write_json(out / "meta" / "stats.json", _stats(rows, episodes, cams))
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


def _write_video(episodes: Sequence[Episode], cam: str, out: Path, fps: float) -> dict[str, Any]:
    """Encode camera ``cam`` of every episode, one after the other, into one MP4; its video info."""
    import av

    path = out / VIDEO_PATH.format(video_key=f"observation.images.{cam}", chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True)
    rate = Fraction(fps).limit_denominator(1000)
    h, w = episodes[0].images[cam].shape[1:3]
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=rate, options={"g": "2", "crf": "23"})
        stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
        stream.time_base = 1 / rate
        k = 0
        for ep in episodes:
            for img in ep.images[cam]:
                frame = av.VideoFrame.from_ndarray(img, format="rgb24")
                frame.pts = k
                k += 1
                container.mux(stream.encode(frame))
        container.mux(stream.encode())
    return {"video.height": int(h), "video.width": int(w), "video.codec": VIDEO_CODEC,
            "video.pix_fmt": "yuv420p", "video.is_depth_map": False, "video.fps": fps,
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
        "index_columns": ["task"], "column_indexes": [],
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


def _stats(rows: dict[str, Any], episodes: Sequence[Episode], cams: Sequence[str]) -> dict[str, Any]:
    """meta/stats.json: min, max, mean, std and count of every numeric column and (per channel, in
    0..1) of every camera."""
    out: dict[str, Any] = {}
    for key, col in rows.items():
        x = np.asarray(col.flatten() if hasattr(col, "flatten") else col, float)
        x = x.reshape(len(col), -1).astype(np.float64)
        out[key] = {"min": x.min(0).tolist(), "max": x.max(0).tolist(), "mean": x.mean(0).tolist(),
                    "std": x.std(0).tolist(), "count": [len(x)]}
    for cam in cams:
        sample = np.concatenate([ep.images[cam][::10] for ep in episodes])  # every 10th frame
        px = sample.reshape(-1, 3) / 255.0
        shape = (3, 1, 1)
        out[f"observation.images.{cam}"] = {
            k: np.asarray(v).reshape(shape).tolist()
            for k, v in (("min", px.min(0)), ("max", px.max(0)), ("mean", px.mean(0)), ("std", px.std(0)))
        } | {"count": [len(sample)]}
    return out
