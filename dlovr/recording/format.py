"""The recording file format: profile, version, channels, attachment names, message schemas.

A recording is an MCAP file that holds everything needed to replay a demonstration with nothing else:

- the scene (its TOML and meshes) as attachments, with a content hash in the metadata;
- software versions (dlovr, mujoco) and the time step as metadata;
- ``/dlovr/command``: the gripper command (target pose) of every step, 50 steps a message;
- ``/dlovr/checkpoint``: full simulator states (``mjSTATE_INTEGRATION``) at the start and every second;
- ``/dlovr/contact_states``: the contact situations (topological, discrete, forces, transitions) each
  time they change, written in chunks of their own so batch readers skip the bulk data;
- ``/dlovr/wrench``: the gripper's wrench (force N, torque N m, world frame) every
  :data:`WRENCH_EVERY` steps, in messages of one second, in chunks of their own like the contact
  states: the compiler derives the detection thresholds from it. Optional: files recorded before it
  existed lack it and the compiler then uses its defaults (marked as such), so the format version
  stays 2 (a reader needs to know nothing new to read either kind);
- ``/dlovr/warnings``: a message per stretch of steps where the simulation was physically implausible
  (a cable point deeper in an obstacle or faster than :mod:`dlovr.plausibility`'s bounds).
  Optional like the wrench: files recorded before it existed have none;
- ``/foxglove/scene`` (``foxglove.SceneUpdate``) and ``/tf`` (``foxglove.FrameTransforms``) at ~30 Hz
  so that Foxglove can show the cable, the gripper and the obstacles.

Timestamps are ``t0_ns + step * dt_ns`` (uint64 ns). Messages are JSON; floats are written with
Python's shortest round-trip repr (:func:`dumps`), so states and commands come back bit for bit.
"""

from __future__ import annotations

import json
import struct
from typing import Any

import numpy as np

from dlovr.inputs import InputError

FORMAT_VERSION = "2"  # 2: commands in messages of 50 steps, an end marker in the states
PROFILE = "dlovr"
TOPIC_COMMAND = "/dlovr/command"
TOPIC_CHECKPOINT = "/dlovr/checkpoint"
TOPIC_STATES = "/dlovr/contact_states"
TOPIC_SCENE = "/foxglove/scene"
TOPIC_TF = "/tf"
TOPIC_WRENCH = "/dlovr/wrench"
TOPIC_WARNINGS = "/dlovr/warnings"
REQUIRED_TOPICS = (TOPIC_COMMAND, TOPIC_CHECKPOINT, TOPIC_STATES)
CHANNELS = (
    (TOPIC_COMMAND, "dlovr.Commands"),
    (TOPIC_CHECKPOINT, "dlovr.Checkpoint"),
    (TOPIC_STATES, "dlovr.ContactState"),
    (TOPIC_SCENE, "foxglove.SceneUpdate"),
    (TOPIC_TF, "foxglove.FrameTransforms"),
    (TOPIC_WRENCH, "dlovr.Wrench"),
    (TOPIC_WARNINGS, "dlovr.Warning"),
)
"""Topics and schema names in the order the writer registers them: channel and schema ids 1, 2, ...
(``dlovr recover`` relies on it when a file's channel definitions were lost)."""
SCENE_PREFIX = "scene/"
SCENE_TOML = "scene/scene.toml"
PIECES_JSON = "model/pieces.json"
MAX_ATTACHMENT_BYTES = 64 * 1024 * 1024
MCAP_MAGIC = b"\x89MCAP0\r\n"


class RecordingError(InputError):
    """A recording cannot be used; the message names the file and the problem in one line."""


def _decode_errors() -> tuple[type[BaseException], ...]:
    import zstandard
    from mcap.exceptions import McapError

    return (
        McapError,  # bad magic, record too long, unsupported compression, end of file
        ValueError,  # CRC mismatches, bad JSON, bad UTF-8, malformed numbers
        zstandard.ZstdError,
        RuntimeError,  # lz4.frame
        struct.error,  # truncated or malformed records
        EOFError,
        KeyError,
        IndexError,
        TypeError,  # a JSON value of the wrong type
        OverflowError,
        MemoryError,  # a damaged length field
        OSError,
    )


DECODE_ERRORS: tuple[type[BaseException], ...] = _decode_errors()
"""Every exception that decoding damaged bytes can raise (MCAP records, zstd/lz4, CRC, JSON, fields):
readers turn them into one :class:`RecordingError` line naming the file."""


def one_line(e: BaseException) -> str:
    """An exception as one short line (its first line, or its type's name); a ``KeyError`` says which
    field is missing (``field 't' missing``, not Python's bare ``'t'``)."""
    if type(e) is KeyError:
        return f"field {str(e.args[0])[:80]!r} missing" if e.args else "a field is missing"
    s = str(e).strip().splitlines()
    return (s[0] if s else type(e).__name__)[:200]


COMMAND_SCHEMA = {
    "title": "dlovr.Commands",
    "description": "Gripper target poses commanded for consecutive steps, starting at `step`: "
    "pos[i] m (world) and quat[i] wxyz are applied before step `step + i`.",
    "type": "object",
    "properties": {
        "step": {"type": "integer"},
        "pos": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
        "quat": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
    },
}
COMMAND_BATCH = 50
"""Steps per command message (0.1 s at 2 ms): one message a step would cost more than the rest."""
CHECKPOINT_SCHEMA = {
    "title": "dlovr.Checkpoint",
    "description": "Full simulator state (mjSTATE_INTEGRATION) after `step` steps, plus the gripper target.",
    "type": "object",
    "properties": {
        "step": {"type": "integer"},
        "state": {"type": "array", "items": {"type": "number"}},
        "target_pos": {"type": "array", "items": {"type": "number"}},
        "target_quat": {"type": "array", "items": {"type": "number"}},
    },
}
STATES_SCHEMA = {
    "title": "dlovr.ContactState",
    "description": "A contact situation when it began: topological and discrete notation, classes of the "
    "transition into it, and per contact its discrete state, faces, contact vector and normal force (N).",
    "type": "object",
    "properties": {
        "t": {"type": "number"},
        "step": {"type": "integer"},
        "topological": {"type": "string"},
        "discrete": {"type": "string"},
        "classes": {"type": "array", "items": {"type": "string"}},
        "contacts": {"type": "array", "items": {"type": "object"}},
    },
}
WRENCH_SCHEMA = {
    "title": "dlovr.Wrench",
    "description": "The gripper's wrench (the load of the holding constraints, as a wrist sensor reads "
    "it) sampled every `every` steps: at simulated times t[i] (s), force[i] (N) and torque[i] (N m, "
    "about the gripper's origin), world frame.",
    "type": "object",
    "properties": {
        "step": {"type": "integer"},
        "every": {"type": "integer"},
        "t": {"type": "array", "items": {"type": "number"}},
        "force": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
        "torque": {"type": "array", "items": {"type": "array", "items": {"type": "number"}}},
    },
}
WARNING_SCHEMA = {
    "title": "dlovr.Warning",
    "description": "A stretch of steps where the simulation was physically implausible "
    "(dlovr.plausibility): kind (penetration or speed), from t to end (s), the step it began, "
    "its peak (m of penetration, m/s of a cable point's speed), the bound it passed (same unit) and "
    "where (the obstacle, or the cable point).",
    "type": "object",
    "properties": {
        "kind": {"type": "string"},
        "t": {"type": "number"},
        "end": {"type": "number"},
        "step": {"type": "integer"},
        "peak": {"type": "number"},
        "bound": {"type": "number"},
        "where": {"type": "string"},
    },
    "required": ["kind", "t", "end", "step", "peak", "bound", "where"],
}
WRENCH_EVERY = 5
"""Steps between two wrench samples (10 ms at 2 ms): enough for the force steps of transitions."""


def dumps(obj: Any) -> bytes:
    """A message as compact JSON bytes (no NaN or infinity; floats in shortest round-trip repr)."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


def floats(a: Any) -> list[float]:
    """A vector or array as a flat list of Python floats."""
    return np.asarray(a, dtype=float).ravel().tolist()
