"""Demonstration recordings as MCAP files: writing, reading, replay, recovery, compiling.

- :mod:`dlovr.recording.format`: what a file holds (profile, version, channels, attachment names,
  message schemas) and :class:`RecordingError`;
- :mod:`dlovr.recording.bundle`: :class:`SceneBundle`, the embedded scene (TOML and meshes), and the
  obstacles' convex pieces as JSON;
- :mod:`dlovr.recording.foxglove`: the ``SceneUpdate`` and ``FrameTransforms`` messages Foxglove shows;
- :mod:`dlovr.recording.writer`: :class:`Recorder` (the file) and :class:`DemoRecorder` (a running
  demonstration), :func:`finish_on_sigterm`, :class:`StopSignals` (stopping between two steps on a
  signal);
- :mod:`dlovr.recording.reader`: :class:`Recording`, a validated file opened for reading, and
  :func:`kept_states`, its debounced contact situations;
- :mod:`dlovr.recording.replaying`: :func:`replay`, re-simulating a recording bit for bit;
- :mod:`dlovr.recording.integrity`: whole-file checksums and a tolerant scan of damaged files;
- :mod:`dlovr.recording.recovery`: :func:`recover`, rescuing a damaged file or one whose writer was
  killed;
- :mod:`dlovr.recording.compile`: :func:`compile_recording` (:func:`compile_noted`: with what it warns
  of) and batch compilation with a cache;
- :mod:`dlovr.recording.scripted`: :func:`~dlovr.recording.scripted.play_script`, a demonstration
  script played on a simulator and recorded (``dlovr demo``, ``dlovr record``);
- :mod:`dlovr.recording.network_html`: a transition network as a self-contained HTML page.
"""

from dlovr.recording.bundle import SceneBundle, pieces_from_json, pieces_to_json
from dlovr.recording.compile import (
    CompileResult,
    check_unique_outputs,
    compile_noted,
    compile_one,
    compile_recording,
    find_recordings,
    record_compiled,
)
from dlovr.recording.format import (
    FORMAT_VERSION,
    PROFILE,
    TOPIC_CHECKPOINT,
    TOPIC_COMMAND,
    TOPIC_SCENE,
    TOPIC_STATES,
    TOPIC_TF,
    RecordingError,
)
from dlovr.recording.reader import Checkpoint, Recording, kept_states, situation_from_payload
from dlovr.recording.recovery import RecoveryReport, recover
from dlovr.recording.replaying import ReplayResult, load_embedded_scene, replay
from dlovr.recording.writer import DemoRecorder, Recorder, StopSignals, finish_on_sigterm

__all__ = [
    "FORMAT_VERSION",
    "PROFILE",
    "TOPIC_CHECKPOINT",
    "TOPIC_COMMAND",
    "TOPIC_SCENE",
    "TOPIC_STATES",
    "TOPIC_TF",
    "Checkpoint",
    "CompileResult",
    "DemoRecorder",
    "Recorder",
    "Recording",
    "RecordingError",
    "RecoveryReport",
    "ReplayResult",
    "SceneBundle",
    "StopSignals",
    "check_unique_outputs",
    "compile_noted",
    "compile_one",
    "compile_recording",
    "find_recordings",
    "finish_on_sigterm",
    "kept_states",
    "load_embedded_scene",
    "pieces_from_json",
    "pieces_to_json",
    "record_compiled",
    "recover",
    "replay",
    "situation_from_payload",
]
