"""The MCAP recording format: writing, validated reading, tamper/corruption errors, recovery."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from mcap_edit import rewrite_mcap

from dlovr.recording import (
    TOPIC_CHECKPOINT,
    TOPIC_COMMAND,
    TOPIC_STATES,
    Recorder,
    Recording,
    RecordingError,
    SceneBundle,
    recover,
)

TOML = b'name = "t"\n[[objects]]\nname = "m"\nmesh = "meshes/m.obj"\n'


def bundle():
    return SceneBundle(TOML, (("meshes/m.obj", b"v 0 0 0\n"),))


def write(path, steps=200, flush_interval=2.0):
    rng = np.random.default_rng(0)
    with Recorder(
        path, bundle(), scene_name="t", dt=0.002, flush_interval=flush_interval, t0_ns=10**18
    ) as rec:
        rec.checkpoint(0, rng.standard_normal(50), [0, 0, 1], [1, 0, 0, 0])
        for k in range(1, steps + 1):
            rec.command(k, rng.standard_normal(3), [1.0, 0.0, 0.0, 0.0])
            if k % 50 == 0:
                rec.contact_state(
                    k, {"t": k * 0.002, "step": k, "discrete": "V/G & E/N & V/N", "classes": []}
                )
            if k % 17 == 0:
                obstacles = [("box", rng.standard_normal((4, 3, 3)))] if k == 17 else ()
                rec.frame(k, rng.standard_normal((5, 3)), [0, 0, 1], [1, 0, 0, 0], 0.005, obstacles)
        rec.checkpoint(steps, rng.standard_normal(50), [0, 0, 1], [1, 0, 0, 0])


def test_roundtrip_is_bit_exact(tmp_path):
    p = tmp_path / "a.mcap"
    write(p)
    r = Recording(p)
    rng = np.random.default_rng(0)
    first_state = rng.standard_normal(50)
    steps, _pos, quat = r.commands()
    assert np.array_equal(quat[0], [1.0, 0.0, 0.0, 0.0])
    assert steps[0] == 1 and len(steps) == 200
    cps = r.checkpoints()
    assert cps[0].step == 0 and np.array_equal(cps[0].state, first_state)  # bit for bit
    assert [s["step"] for s in r.states()] == [50, 100, 150, 200]
    assert r.metadata["format_version"] == "2" and r.metadata["mujoco_version"]
    assert r.scene == bundle()
    assert r.count(TOPIC_COMMAND) == 4 and r.count(TOPIC_CHECKPOINT) == 2  # 50 steps a message


def test_contact_states_are_in_chunks_of_their_own(tmp_path):
    from mcap.reader import make_reader

    p = tmp_path / "a.mcap"
    write(p)
    with open(p, "rb") as fh:
        summary = make_reader(fh).get_summary()
    states_id = next(c.id for c in summary.channels.values() if c.topic == TOPIC_STATES)
    for ci in summary.chunk_indexes:
        ids = set(ci.message_index_offsets)
        if states_id in ids:
            assert ids == {states_id}


def test_scene_bundle_materializes_only_safe_paths(tmp_path):
    out = bundle().materialize(tmp_path / "s")
    assert out.read_bytes() == TOML and (tmp_path / "s/meshes/m.obj").exists()
    for bad in ("../evil.obj", "/etc/passwd", "a/../../b"):
        with pytest.raises(RecordingError, match="unsafe"):
            SceneBundle(TOML, ((bad, b""),)).materialize(tmp_path / "x")


@pytest.mark.parametrize(
    ("mangle", "message"),
    [
        (lambda b: b"", "empty file"),
        (lambda b: b"hello world, not mcap" * 10, "not an MCAP file"),
        (lambda b: b[: len(b) // 2], "truncated"),
        (lambda b: b[:3000] + bytes(x ^ 0xFF for x in b[3000:3100]) + b[3100:], "corrupt"),
    ],
    ids=["empty", "not-mcap", "truncated", "corrupt-bytes"],
)
def test_bad_files_give_one_clear_error(tmp_path, mangle, message):
    p = tmp_path / "a.mcap"
    write(p)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(mangle(p.read_bytes()))
    with pytest.raises(RecordingError, match=message) as ei:
        r = Recording(bad)
        _ = (r.commands(), r.checkpoints(), r.states())  # reading them is what raises
    assert str(bad) in str(ei.value) and "\n" not in str(ei.value)


def test_tampered_scene_is_detected(tmp_path):
    p = tmp_path / "a.mcap"
    write(p)
    r = Recording(p)
    out = tmp_path / "t.mcap"  # a modified scene attachment under the old metadata
    rewrite_mcap(
        p, out, attachment=lambda name, data: data + b"# evil\n" if name == "scene/scene.toml" else data
    )
    assert r.scene.digest
    with pytest.raises(RecordingError, match="embedded scene was modified"):
        Recording(out)


def test_missing_channel_is_named(tmp_path):
    from mcap.writer import Writer

    p = tmp_path / "x.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh, enable_data_crcs=True)
        w.start(profile="dlovr")
        w.add_metadata(
            "dlovr",
            {"scene_sha256": bundle().digest, "scene_name": "t", "timestep": "0.002", "t0_ns": "0",
             "format_version": "2"},
        )
        w.add_attachment(0, 0, "scene/scene.toml", "application/toml", TOML)
        w.add_attachment(0, 0, "scene/meshes/m.obj", "application/octet-stream", b"v 0 0 0\n")
        sid = w.register_schema("x", "jsonschema", b"{}")
        w.register_channel(TOPIC_COMMAND, "json", sid)
        w.finish()
    with pytest.raises(RecordingError, match="no channel /dlovr/checkpoint"):
        Recording(p)


WRITER = textwrap.dedent(
    """
    import sys, time
    import numpy as np
    from dlovr.recording import Recorder, SceneBundle
    b = SceneBundle(b'name = "t"\\n', ())
    rec = Recorder(sys.argv[1], b, scene_name="t", dt=0.002, flush_interval=0.2, t0_ns=0)
    rec.checkpoint(0, np.zeros(10), [0, 0, 1], [1, 0, 0, 0])
    k = 0
    while True:
        k += 1
        rec.command(k, [k * 1e-3, 0, 0], [1, 0, 0, 0])
        if k % 100 == 0:
            rec.contact_state(k, {"step": k})
        if k % 500 == 0:
            rec.checkpoint(k, np.zeros(10), [0, 0, 1], [1, 0, 0, 0])
        if k == 2000:
            print("ready", flush=True)
        time.sleep(0.0002)
    """
)


def test_killed_writer_is_recovered_up_to_its_last_checkpoint(tmp_path):
    p = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(p)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(0.6)
    proc.kill()
    proc.wait()
    with pytest.raises(RecordingError, match="truncated"):
        Recording(p)
    fixed = tmp_path / "fixed.mcap"
    rep = recover(p, fixed)
    r = Recording(fixed)
    steps, pos, _ = r.commands()
    assert steps[0] == 1 and len(steps) >= 2000 and rep.messages > 40  # commands: 50 steps a message
    assert steps[-1] == r.checkpoints()[-1].step and steps[-1] % 500 == 0  # cut at the last checkpoint
    assert np.array_equal(pos[:, 0], steps * 1e-3)  # every recovered message intact, in order
    assert [s["step"] for s in r.states()] == list(range(100, steps[-1] + 1, 100))  # all, none after
    json.dumps(r.metadata)


def test_foxglove_messages_validate_against_foxglove_schemas(tmp_path):
    import jsonschema
    from mcap.reader import make_reader

    p = tmp_path / "a.mcap"
    write(p)
    seen = set()
    with open(p, "rb") as fh:
        for schema, channel, msg in make_reader(fh).iter_messages(topics=["/foxglove/scene", "/tf"]):
            jsonschema.validate(json.loads(msg.data), json.loads(schema.data))
            seen.add((channel.topic, schema.name))
    assert seen == {("/foxglove/scene", "foxglove.SceneUpdate"), ("/tf", "foxglove.FrameTransforms")}


def test_other_format_version_is_a_clear_error(tmp_path):
    p = tmp_path / "a.mcap"
    write(p)
    old = tmp_path / "old.mcap"
    rewrite_mcap(p, old, metadata=lambda name, d: {**d, "format_version": "1"})
    with pytest.raises(RecordingError, match=r"recording format 1, this dlovr .* reads format 2"):
        Recording(old)
