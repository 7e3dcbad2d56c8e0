"""Recordings as learning datasets (`dlovr export`, `dlovr generate`): each exported dataset read back
with readers independent of dlovr's writers (pyarrow and PyAV for LeRobot v3.0, h5py for robomimic)
and checked against the recording itself: its checkpoints bit for bit (float64) or to float32
rounding, its debounced contact situations, timestamps, fps and shapes."""

from __future__ import annotations

import json
import math
import os
import shutil
import sys
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from dlovr.cli import main
from dlovr.datasets import CABLE_NODES, LABELS, gather_episode, write_dataset
from dlovr.datasets.frames import frame_steps, resample_cable
from dlovr.datasets.lerobot import state_vector
from dlovr.recording import Recording
from dlovr.recording.compile import compile_recording
from dlovr.recording.reader import kept_states

ROOT = Path(__file__).resolve().parent.parent
TOUCH = Path(__file__).parent / "data" / "touch_table.script.toml"
FPS = 30
W, H = 64, 48


def _h5(path: Path) -> Any:
    """An HDF5 file open for reading (typed loosely: h5py's items are groups, datasets or more)."""
    return h5py.File(path, "r")


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The touch-table demonstration recorded, and exported (scene and gripper cameras, 64x48) to both
    formats: (recording, LeRobot folder, robomimic file)."""
    d = tmp_path_factory.mktemp("datasets")
    rec = d / "touch.mcap"
    r = cli("record", "--script", TOUCH, "-o", rec)
    assert r.exit_code == 0, r.output
    lr, rm = d / "lerobot", d / "touch.hdf5"
    r = cli("export", rec, "--format", "lerobot", "-o", lr, "--fps", FPS, "--cameras", "scene,gripper",
            "--size", f"{W}x{H}")
    assert r.exit_code == 0, r.output
    assert "wrote 1 episodes" in r.output
    ep = gather_episode(rec, FPS, ("scene", "gripper"), (W, H))  # the same through the API
    write_dataset([ep], rm, "robomimic", "touch the table")
    return rec, lr, rm


def _expected_frames(rec: Recording) -> tuple[int, np.ndarray]:
    """The first checkpoint's step and the frames' steps, worked out from the recording."""
    cps = rec.checkpoints()
    steps = rec.commands()[0]
    return cps[0].step, cps[0].step + frame_steps(len(steps), FPS, rec.dt)


def _situation_at(kept, t: float) -> str:
    """The recorded (debounced) situation holding at time ``t``."""
    i = max(k for k, s in enumerate(kept) if s.t <= t + 1e-12) if kept[0].t <= t else 0
    return kept[i].situation.format()


@pytest.mark.slow  # shares one recorded and exported demonstration (~15 s CPU)
def test_robomimic_states_are_the_recordings_checkpoints_bit_for_bit(exported):
    path, _, rm = exported
    rec = Recording(path)
    _, steps = _expected_frames(rec)
    with _h5(rm) as f:
        demo = f["data/demo_0"]
        states = demo["states"][()]
        assert states.dtype == np.float64 and len(states) == len(steps) == demo.attrs["num_samples"]
        by_step = {c.step: c.state for c in rec.checkpoints()}
        on = [(j, by_step[int(s)]) for j, s in enumerate(steps) if int(s) in by_step]
        assert len(on) >= 3  # frame 30 k lies on checkpoint k at 30 fps
        for j, want in on:
            assert np.array_equal(states[j].view(np.uint64), want.view(np.uint64)), f"frame {j}"
        np.testing.assert_allclose(demo["obs/sim_time"][()], steps * rec.dt, rtol=0, atol=1e-9)


@pytest.mark.slow  # shares one recorded and exported demonstration (~15 s CPU)
def test_lerobot_state_is_the_robomimic_state_to_float32(exported):
    _, lr, rm = exported
    table = pq.read_table(lr / "data" / "chunk-000" / "file-000.parquet")
    state = np.array(table.column("observation.state").to_pylist(), dtype=np.float32)
    with _h5(rm) as f:
        o = f["data/demo_0/obs"]
        n = len(state)
        full = np.concatenate([o["gripper_pos"][()], o["gripper_quat"][()], o["gripper_wrench"][()],
                               o["cable"][()].reshape(n, -1), o["object_poses"][()].reshape(n, -1)], axis=1)
        assert o["cable"].shape == (n, CABLE_NODES, 3)
        assert np.array_equal(state, full.astype(np.float32))
        action = np.array(table.column("action").to_pylist(), dtype=np.float32)
        assert np.array_equal(action, f["data/demo_0/actions"][()].astype(np.float32))


@pytest.mark.slow  # shares one recorded and exported demonstration (~15 s CPU)
def test_lerobot_reads_back_with_pyarrow_and_pyav(exported):
    import av

    path, lr, _ = exported
    rec = Recording(path)
    _, steps = _expected_frames(rec)
    info = json.loads((lr / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == FPS
    assert info["total_episodes"] == 1 and info["total_frames"] == len(steps)
    table = pq.read_table(lr / "data" / "chunk-000" / "file-000.parquet")
    assert table.num_rows == len(steps)
    for name, feat in info["features"].items():
        if feat["dtype"] == "video":
            continue
        col = table.column(name).to_pylist()
        width = feat["shape"][0]
        assert all((len(v) if isinstance(v, list) else 1) == width for v in col), name
    ts = np.array(table.column("timestamp").to_pylist())
    np.testing.assert_allclose(ts, np.arange(len(steps)) / FPS, atol=1e-6)
    assert table.column("frame_index").to_pylist() == list(range(len(steps)))
    eps = pq.read_table(lr / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pylist()
    assert eps[0]["length"] == len(steps) and eps[0]["dlovr/success"] is True
    assert pq.read_table(lr / "meta" / "tasks.parquet").column("task_index").to_pylist() == [0]
    for cam in ("scene", "gripper"):
        key = f"observation.images.{cam}"
        assert info["features"][key]["shape"] == [H, W, 3]
        video = lr / info["video_path"].format(video_key=key, chunk_index=0, file_index=0)
        with av.open(str(video)) as c:
            stream = c.streams.video[0]
            assert stream.average_rate == FPS and stream.frames == len(steps)
            frame = next(c.decode(video=0))
            img = frame.to_ndarray(format="rgb24")
        assert img.shape == (H, W, 3) and img.std() > 1  # a picture, not a blank
        assert eps[0][f"videos/{key}/to_timestamp"] == pytest.approx(len(steps) / FPS)


#: LeRobot's own reader, run in a child interpreter: this one if it imports ``lerobot``, else the one
#: ``DLOVR_LEROBOT_PYTHON`` names (lerobot pins torch and numpy: it may live in its own venv).
LEROBOT_READ = """
import json, sys
import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset
root, out, fps = sys.argv[1], sys.argv[2], float(sys.argv[3])
ahead = {"action": [0.0, 1 / fps]}  # each frame's action and the next one's
ds = LeRobotDataset("local/dlovr", root=root, video_backend="pyav", delta_timestamps=ahead)
picks = sorted({0, len(ds) // 2, len(ds) - 1})
items = [ds[i] for i in picks]
arrays = {"state": np.stack([f["observation.state"].numpy() for f in items]),
          "action": np.stack([f["action"].numpy() for f in items]),
          "action_is_pad": np.stack([f["action_is_pad"].numpy() for f in items])}
for cam in ds.meta.camera_keys:
    arrays[cam] = np.stack([f[cam].numpy() for f in items])
np.savez(out, picks=np.array(picks), **arrays)
print(json.dumps({"frames": ds.num_frames, "episodes": ds.num_episodes, "fps": ds.fps,
                  "cameras": sorted(ds.meta.camera_keys),
                  "timestamps": [float(f["timestamp"]) for f in items]}))
"""


@pytest.fixture(scope="module")
def lerobot_python() -> str:
    """An interpreter that imports ``lerobot`` (see :data:`LEROBOT_READ`); skips where there is none."""
    import importlib.util
    import os
    import subprocess

    if importlib.util.find_spec("lerobot") is not None:
        return sys.executable
    other = os.environ.get("DLOVR_LEROBOT_PYTHON")
    if other and subprocess.run([other, "-c", "import lerobot"], capture_output=True).returncode == 0:
        return other
    pytest.skip("lerobot is not installed (optional: DLOVR_LEROBOT_PYTHON may name a python that has it)")


@pytest.mark.slow  # shares one recorded and exported demonstration (~15 s CPU); imports torch
def test_lerobots_own_reader_loads_the_dataset(lerobot_python, exported, tmp_path):
    """LeRobot's ``LeRobotDataset`` (optional, docs/datasets.md) reads the exported folder: frames,
    fps, cameras, states, actions with a look-ahead, and the decoded camera images equal PyAV's."""
    import subprocess

    import av

    _, lr, _ = exported
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"HF_HUB_OFFLINE": "1"}
    r = subprocess.run([lerobot_python, "-c", LEROBOT_READ, str(lr), str(tmp_path / "got.npz"), str(FPS)],
                       capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    seen = json.loads(r.stdout.strip().splitlines()[-1])
    table = pq.read_table(lr / "data" / "chunk-000" / "file-000.parquet")
    got = np.load(tmp_path / "got.npz")
    picks = got["picks"]
    assert seen["frames"] == table.num_rows and seen["episodes"] == 1 and seen["fps"] == FPS
    assert seen["cameras"] == ["observation.images.gripper", "observation.images.scene"]
    np.testing.assert_allclose(seen["timestamps"], picks / FPS, atol=1e-6)
    state = np.array(table.column("observation.state").to_pylist(), dtype=np.float32)
    action = np.array(table.column("action").to_pylist(), dtype=np.float32)
    assert np.array_equal(got["state"], state[picks])
    nxt = np.minimum(picks + 1, len(action) - 1)  # past the last frame LeRobot pads with the last
    assert np.array_equal(got["action"], np.stack([action[picks], action[nxt]], axis=1))
    assert got["action_is_pad"][:, 1].tolist() == [bool(p == len(action) - 1) for p in picks]
    for key in seen["cameras"]:
        with av.open(str(lr / "videos" / key / "chunk-000" / "file-000.mp4")) as c:
            frames = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
        want = np.stack([frames[p] for p in picks]).transpose(0, 3, 1, 2) / 255.0  # CHW, 0..1
        assert np.abs(got[key] - want).max() < 1e-6, key


@pytest.mark.slow  # shares one recorded and exported demonstration (~15 s CPU)
def test_labels_are_the_recordings_situations(exported):
    path, lr, rm = exported
    rec = Recording(path)
    kept = kept_states(rec)
    _, steps = _expected_frames(rec)
    want = [_situation_at(kept, s * rec.dt) for s in steps]
    vocab = json.loads((lr / "meta" / "labels.json").read_text())
    table = pq.read_table(lr / "data" / "chunk-000" / "file-000.parquet")
    codes = table.column("label.situation").to_pylist()
    assert [vocab["situation"][c] for c in codes] == want
    with _h5(rm) as f:
        labels = f["data/demo_0/labels"]
        assert [s.decode() for s in labels["situation"][()]] == want
        assert set(labels) == {*LABELS, "macro_index"}
        transitions = [s.decode() for s in labels["transition"][()]]
        stability = {s.decode() for s in labels["stability"][()]}
        macro = labels["macro_index"][()]
    assert len(want) > 1 and len(set(want)) > 1  # the demonstration touches the table
    program = compile_recording(path)  # the recording's transitions and macros
    t = steps * rec.dt
    for m in program.macros:
        j = int(np.searchsorted(t, m.t - 1e-9))
        if m.kind == "transition" and ",".join(m.classes) not in transitions[j].split(";"):
            # the program took a swing through free space as one step (docs/model.md section 6): the
            # labels keep the landing, its transition out of the brief free situation before it
            touching = ["[" in s.situation.format() for s in kept if s.t < m.t - 1e-9]  # any object
            assert transitions[j] and touching[-2] and not touching[-1], (m.index, m.t, transitions[j])
        last = int(np.searchsorted(t, m.t + 1e-9, side="right")) - 1  # the macro's last frame
        assert macro[last] == m.index and (last + 1 == len(t) or macro[last + 1] != m.index)
    assert sum(1 for x in transitions if x) >= sum(m.kind == "transition" for m in program.macros) >= 1
    assert stability <= {"free", "stable", "semi-stable", "instable"}
    assert macro[0] >= 1 and np.all(np.diff(macro[macro > 0]) >= 0)


@pytest.mark.slow  # shares one recorded and exported demonstration (~15 s CPU)
def test_robomimic_episode_holds_its_scene_and_model(exported):
    import mujoco

    path, _, rm = exported
    rec = Recording(path)
    with _h5(rm) as f:
        assert json.loads(f["data"].attrs["env_args"])["env_name"] == "dlovr"
        demo = f["data/demo_0"]
        assert demo.attrs["scene_toml"] == rec.scene.toml.decode()
        model = mujoco.MjModel.from_xml_string(demo.attrs["model_file"])
        size = mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_INTEGRATION)
        assert demo["states"].shape[1] == size
        assert demo["obs/scene_image"].shape[1:] == (H, W, 3)
        assert demo["dones"][-1] == 1 and demo["rewards"][-1] == 1.0


def test_resample_cable_keeps_the_ends_and_spaces_evenly():
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 3, 0]], float)
    out = resample_cable(pts, 5)
    np.testing.assert_allclose(out[0], pts[0])
    np.testing.assert_allclose(out[-1], pts[-1])
    np.testing.assert_allclose(np.linalg.norm(np.diff(out, axis=0), axis=1), 1.0)


def test_frame_steps_are_the_nearest_steps():
    steps = frame_steps(1000, 30, 0.002)
    assert steps[0] == 0 and steps[30] == 500 and steps[60] == 1000 and len(steps) == 61
    assert np.all(np.abs(steps * 0.002 - np.arange(61) / 30) <= 0.001 + 1e-12)
    assert math.isclose(frame_steps(10, 500, 0.002)[-1], 10)


@pytest.mark.parametrize(
    "args,message",
    [
        (["--fps", "0"], "--fps: must be > 0"),
        (["--fps", "abc"], "--fps: 'abc' is not a number"),
        (["--size", "64"], "--size: '64' is not WIDTHxHEIGHT"),
        (["--size", "65x48"], "--size: image size 65x48"),
        (["--cameras", "top"], "--cameras: unknown camera 'top'"),
        (["--format", "zarr"], "--format: 'zarr' is not one of lerobot, robomimic"),
    ],
)
def test_bad_options_are_one_line_exit_2(tmp_path, args, message):
    r = cli("export", ROOT / "recordings" / "l_block.mcap", "-o", tmp_path / "out", *args)
    assert r.exit_code == 2 and message in r.output and len(r.output.strip().splitlines()) == 1, r.output
    assert not (tmp_path / "out").exists()


@pytest.mark.slow  # shares one recorded and exported demonstration (~15 s CPU)
def test_an_existing_output_is_not_overwritten_without_force(exported, tmp_path):
    path, lr, _ = exported
    before = (lr / "meta" / "info.json").read_bytes()
    r = cli("export", path, "-o", lr)
    assert r.exit_code == 2 and "exists (give --force to replace it)" in r.output
    assert (lr / "meta" / "info.json").read_bytes() == before
    other = tmp_path / "notes.hdf5"
    other.mkdir()
    r = cli("export", path, "--format", "robomimic", "-o", other, "--force")
    assert r.exit_code == 2 and "is not a robomimic dataset" in r.output
    r = cli("export", path, "--format", "robomimic", "-o", tmp_path / "x.txt")
    assert r.exit_code == 2 and "one .hdf5 file" in r.output


@pytest.mark.slow  # shares one recorded and exported demonstration (~15 s CPU)
def test_force_replaces_a_dataset(exported, tmp_path):
    path, _, rm = exported
    out = tmp_path / "d.hdf5"
    shutil.copy(rm, out)
    r = cli("export", path, "--format", "robomimic", "-o", out, "--fps", "5", "--force")
    assert r.exit_code == 0, r.output
    with _h5(out) as f:
        assert f["data"].attrs["fps"] == 5
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.hdf5"]  # no temporary left


@pytest.mark.slow
def test_the_sample_recordings_export_to_both_formats(tmp_path):
    samples = sorted((ROOT / "recordings").glob("*.mcap"))
    assert len(samples) == 5
    for s in samples:
        ep = gather_episode(s, FPS)  # one replay, written in both formats
        write_dataset([ep], tmp_path / s.stem, "lerobot", "task")
        write_dataset([ep], tmp_path / f"{s.stem}.hdf5", "robomimic", "task")
        rec = Recording(s)
        by_step = {c.step: c.state for c in rec.checkpoints()}
        with _h5(tmp_path / f"{s.stem}.hdf5") as f:
            states, steps = f["data/demo_0/states"][()], _expected_frames(rec)[1]
            np.testing.assert_allclose(f["data/demo_0/obs/sim_time"][()], steps * rec.dt, rtol=0, atol=1e-9)
        table = pq.read_table(tmp_path / s.stem / "data" / "chunk-000" / "file-000.parquet")
        state32 = np.array(table.column("observation.state").to_pylist(), dtype=np.float32)
        assert np.array_equal(state32, state_vector(ep).astype(np.float32))
        on = [j for j, k in enumerate(steps) if int(k) in by_step]
        regular = [k for k in by_step if (k - steps[0]) % 500 == 0]  # one a second (+ one at the end)
        assert len(on) >= len(regular) >= len(by_step) - 1  # every second's checkpoint is a frame
        for j in on:
            assert np.array_equal(states[j].view(np.uint64), by_step[int(steps[j])].view(np.uint64)), s.name


@pytest.mark.slow
def test_generate_keeps_the_runs_that_run_trials_counts_successful(tmp_path):
    from dlovr.datasets.generate import trial_setup
    from dlovr.execution.trials import run_trials

    program = ROOT / "recordings" / "programs" / "l_block.program.json"
    vary = ("--vary", "dlo.length=10%")
    out = tmp_path / "gen.hdf5"
    r = cli("generate", program, "--episodes", 2, "--seed", 1, *vary, "--format", "robomimic", "-o", out,
            "--fps", 10)
    assert r.exit_code == 0, r.output
    trials = run_trials(trial_setup(str(program), vary[1::2], 1), 2)  # as `dlovr run --trials`, unrecorded
    won = [t for t in trials if t["program"]["success"]]
    assert f"kept {len(won)} of 2 runs" in r.output
    assert won, "no successful trial to compare"
    with _h5(out) as f:
        demos = [f[f"data/demo_{i}"] for i in range(len(f["data"]))]
        assert [int(d.attrs["trial"]) for d in demos] == [t["trial"] for t in won]
        assert [json.loads(d.attrs["vary"]) for d in demos] == [t["values"] for t in won]
        assert all(d.attrs["success"] and d.attrs["seed"] == 1 for d in demos)
        assert all(d.attrs["kind"] == "program run" for d in demos)
    r = cli("generate", program, "--episodes", 2, "-o", out)
    assert r.exit_code == 2 and "exists" in r.output


def test_generate_checks_its_numbers_first(tmp_path):
    program = ROOT / "recordings" / "programs" / "l_block.program.json"
    for args, message in ((["--episodes", "0"], "--episodes: must be >= 1"),
                          (["--episodes", "2", "--workers", "x"], "--workers: 'x' is not an integer"),
                          (["--episodes", "2", "--size", "10x10"], "--size: image size 10x10")):
        r = cli("generate", program, *args, "-o", tmp_path / "o")
        assert r.exit_code == 2 and message in r.output, r.output


def test_generate_on_a_cluster_without_ray_is_one_line_exit_2(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError, as where it is not installed
    program = ROOT / "recordings" / "programs" / "l_block.program.json"
    r = cli("generate", program, "--episodes", "2", "--cluster", "local", "-o", tmp_path / "o")
    assert r.exit_code == 2, r.output
    assert r.output.strip() == "Error: --cluster needs Ray, which is not installed: pip install 'dlovr[ray]'"
    r = cli("generate", program, "--episodes", "2", "--cluster", "nowhere", "-o", tmp_path / "o")
    assert r.exit_code == 2 and "--cluster nowhere: expected local, auto or HOST:PORT" in r.output
    assert not (tmp_path / "o").exists()
