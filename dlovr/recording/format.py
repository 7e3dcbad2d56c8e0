"""The recording file format: profile, version, channels, attachment names, message schemas.

A recording is an MCAP file that holds everything needed to replay a demonstration with nothing else:

- the scene (its TOML and meshes) as attachments, with a content hash in the metadata;
- software versions (dlovr, mujoco) and the time step as metadata;
- ``/dlovr/command``: the gripper command (target pose) of every step, 50 steps a message;
- ``/dlovr/checkpoint``: full simulator states (``mjSTATE_INTEGRATION``) at the start and every second;
- ``/dlovr/contact_states``: the contact situations (topological, discrete, forces, transitions) each
  time they change, written in chunks of their own so batch readers skip the bulk data;
- ``/foxglove/scene`` (``foxglove.SceneUpdate``) and ``/tf`` (``foxglove.FrameTransforms``) at ~30 Hz
  so that Foxglove can show the cable, the gripper and the obstacles.

Timestamps are ``t0_ns + step * dt_ns`` (uint64 ns). Messages are JSON; floats are written with
Python's shortest round-trip repr (:func:`dumps`), so states and commands come back bit for bit.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

FORMAT_VERSION = "2"  # 2: commands in messages of 50 steps, an end marker in the states
PROFILE = "dlovr"
TOPIC_COMMAND = "/dlovr/command"
TOPIC_CHECKPOINT = "/dlovr/checkpoint"
TOPIC_STATES = "/dlovr/contact_states"
TOPIC_SCENE = "/foxglove/scene"
TOPIC_TF = "/tf"
REQUIRED_TOPICS = (TOPIC_COMMAND, TOPIC_CHECKPOINT, TOPIC_STATES)
SCENE_PREFIX = "scene/"
SCENE_TOML = "scene/scene.toml"
PIECES_JSON = "model/pieces.json"
MAX_ATTACHMENT_BYTES = 64 * 1024 * 1024
MCAP_MAGIC = b"\x89MCAP0\r\n"


class RecordingError(ValueError):
    """A recording cannot be used; the message names the file and the problem in one line."""


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


def dumps(obj: Any) -> bytes:
    """A message as compact JSON bytes (no NaN or infinity; floats in shortest round-trip repr)."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


def floats(a: Any) -> list[float]:
    """A vector or array as a flat list of Python floats."""
    return np.asarray(a, dtype=float).ravel().tolist()
