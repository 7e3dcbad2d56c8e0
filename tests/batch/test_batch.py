"""Batch work (dlovr.batch): local processes and Ray give the same results, a killed worker's task runs
again and is reported, nothing is lost; ``dlovr compile --cluster``."""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path
from typing import Any

import pytest
from batch_tasks import always_die, call_or_die, die_once, fail_on, seeded, wait_for
from click.testing import CliRunner

import dlovr
from dlovr.batch import BatchError, Task, run_batch, summarize
from dlovr.cli import main

RECORDINGS = Path(__file__).parents[2] / "recordings"
SEEDS = range(6)


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def run(fn, tasks, **kw):
    return list(run_batch(fn, tasks, progress=False, **kw))


def by_key(results):
    return {r.key: r.value for r in results}


def seed_tasks(*extra, **kwargs):
    return [Task(f"seed{s}", (s, *extra), kwargs) for s in SEEDS]


@pytest.fixture(scope="module")
def ray_instance():
    """One Ray instance for the module: 2 CPUs, no dashboard, bound to 127.0.0.1 (dlovr's own local
    start); its workers import this dlovr and the task module. Skips only where Ray is not installed."""
    ray = pytest.importorskip("ray")

    from dlovr.batch.on_ray import connect

    path = os.pathsep.join(
        [str(Path(dlovr.__file__).parents[1]), str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")]
    )
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PYTHONPATH", path)  # inherited by the raylet, so by the workers
        assert connect(ray, "local", 2)
    try:
        assert ray.cluster_resources()["CPU"] == 2
        assert {n["NodeManagerAddress"] for n in ray.nodes()} == {"127.0.0.1"}
        yield ray
    finally:
        ray.shutdown()


# --------------------------------------------------------------------------------------------------
# Local processes
# --------------------------------------------------------------------------------------------------


def test_in_process_and_worker_processes_give_the_same_values():
    one = run(seeded, seed_tasks(), workers=1)
    two = run(seeded, seed_tasks(), workers=2)
    assert by_key(one) == by_key(two) == {f"seed{s}": seeded(s) for s in SEEDS}
    assert {r.where for r in one} == {f"{os.uname().nodename}:{os.getpid()}"}
    assert str(os.getpid()) not in {r.where.rpartition(":")[2] for r in two}
    assert sorted(r.index for r in two) == list(range(len(SEEDS)))


@pytest.mark.parametrize("how", ["exit", "kill"])
def test_a_worker_that_dies_mid_task_gets_its_task_run_again(tmp_path, how):
    res = run(die_once, seed_tasks(3, str(tmp_path / "m"), how), workers=2)
    assert by_key(res) == {f"seed{s}": seeded(s) for s in SEEDS}  # nothing lost, values as usual
    victim = next(r for r in res if r.key == "seed3")
    assert victim.attempts == 2 and len(victim.lost) == 1
    assert ("exit code 13" if how == "exit" else "killed by SIGKILL") in victim.lost[0]
    assert all(r.attempts == 1 for r in res if r.key != "seed3")
    assert str(summarize(res)) == "6 tasks: 6 done, 0 failed, 1 retried"


def test_a_task_whose_worker_always_dies_is_reported_failed(capsys):
    res = list(run_batch(always_die, seed_tasks(2), workers=2, retries=1))
    bad = next(r for r in res if r.key == "seed2")
    assert not bad.ok and bad.attempts == 2 and "worker lost on each of 2 attempts" in (bad.error or "")
    assert sum(r.ok for r in res) == 5 and summarize(res).failed == 1
    err = capsys.readouterr().err
    assert "running it again" in err and "giving up" in err  # reported as it happens


def test_an_error_in_the_task_is_its_result_not_retried():
    for workers in (1, 2):
        res = run(fail_on, seed_tasks(4), workers=workers)
        bad = next(r for r in res if r.key == "seed4")
        assert bad.error == "ValueError: seed 4 is bad second line" and bad.attempts == 1
        assert summarize(res).ok == 5


def test_results_come_in_order_of_completion(tmp_path):
    tasks = [Task(str(s), (s, str(tmp_path / "m"))) for s in range(3)]
    order = [r.index for r in run(wait_for, tasks, workers=2)]
    assert sorted(order) == [0, 1, 2] and order.index(1) < order.index(0)


def test_bad_batches_are_refused():
    with pytest.raises(ValueError, match="unique"):
        run(seeded, [Task("a", (1,)), Task("a", (2,))])
    with pytest.raises(BatchError, match="expected local, auto or HOST:PORT"):
        run(seeded, seed_tasks(), cluster="nowhere")


# --------------------------------------------------------------------------------------------------
# The command line, without Ray running
# --------------------------------------------------------------------------------------------------


def test_cluster_without_ray_installed_is_one_line_exit_2(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    r = cli("compile", RECORDINGS, "--cluster", "local")
    assert r.exit_code == 2 and r.output.strip().splitlines() == [
        "Error: --cluster needs Ray, which is not installed: pip install 'dlovr[ray]'"
    ]


@pytest.mark.parametrize(
    ("address", "message"),
    [("nowhere", "expected local, auto or HOST:PORT"), ("127.0.0.1:1", "cannot reach the Ray cluster")],
)
def test_bad_or_unreachable_cluster_is_one_line_exit_2(address, message, tmp_path):
    r = cli("compile", RECORDINGS / "table.mcap", "-o", tmp_path, "--cluster", address)
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1 and message in r.output


def test_a_cluster_that_refuses_to_be_joined_is_one_line_with_the_token_hint(monkeypatch):
    """Ray never enables token authentication by itself for an address: when joining fails without it,
    the one line says what to set."""
    import socket
    from types import SimpleNamespace

    from dlovr.batch.on_ray import connect

    def refuse(**kwargs):
        raise ConnectionError("Failed to connect to Ray cluster at the address.\nSee the logs.")

    fake_ray = SimpleNamespace(is_initialized=lambda: False, init=refuse)
    with socket.create_server(("127.0.0.1", 0)) as listening:  # reachable, but not joinable
        address = f"127.0.0.1:{listening.getsockname()[1]}"
        for mode, hint in ((None, True), ("token", False)):
            if mode is None:
                monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
            else:
                monkeypatch.setenv("RAY_AUTH_MODE", mode)
            with pytest.raises(BatchError) as e:
                connect(fake_ray, address, None)
            msg = str(e.value)
            assert msg.startswith(f"cannot join the Ray cluster at {address}: ConnectionError: Failed")
            assert "\n" not in msg and ("set RAY_AUTH_MODE=token and its token" in msg) == hint, msg


# --------------------------------------------------------------------------------------------------
# Ray (one instance for the module)
# --------------------------------------------------------------------------------------------------


def test_ray_gives_the_same_values_as_local_processes(ray_instance):
    on_ray = run(seeded, seed_tasks(), cluster="local")
    assert by_key(on_ray) == by_key(run(seeded, seed_tasks(), workers=2))
    assert all(r.attempts == 1 for r in on_ray)
    assert str(os.getpid()) not in {r.where.rpartition(":")[2] for r in on_ray}  # ran in Ray's workers


def test_ray_runs_a_killed_workers_task_again(ray_instance, tmp_path):
    res = run(die_once, seed_tasks(1, str(tmp_path / "m"), "kill"), cluster="local")
    assert by_key(res) == {f"seed{s}": seeded(s) for s in SEEDS}
    victim = next(r for r in res if r.key == "seed1")
    assert victim.attempts == 2 and "WorkerCrashedError" in victim.lost[0]
    assert str(summarize(res)) == "6 tasks: 6 done, 0 failed, 1 retried"


def test_ray_reports_a_task_whose_worker_always_dies(ray_instance):
    res = run(always_die, seed_tasks(0), cluster="local", retries=1)
    bad = next(r for r in res if r.key == "seed0")
    assert not bad.ok and bad.attempts == 2 and "WorkerCrashedError" in (bad.error or "")
    assert summarize(res).ok == 5


def test_ray_streams_results_in_order_of_completion(ray_instance, tmp_path):
    tasks = [Task(str(s), (s, str(tmp_path / "m"))) for s in range(3)]
    order = [r.index for r in run(wait_for, tasks, cluster="local", workers=2)]
    assert sorted(order) == [0, 1, 2] and order.index(1) < order.index(0)


def test_ray_and_local_processes_draw_the_progress_bar(ray_instance, capsys):
    options: list[dict[str, Any]] = [{"cluster": "local"}, {"workers": 2}]
    for kw in options:
        res = list(run_batch(seeded, seed_tasks(), label="seeding the walks", **kw))
        assert len(res) == len(SEEDS)
        assert "seeding the walks" in capsys.readouterr().err, kw


def _hdf5_items(path: Path) -> dict[str, Any]:
    """Every dataset's bytes and every attribute of an HDF5 file, by path."""
    import h5py

    out: dict[str, Any] = {}

    def visit(name: str, obj: Any) -> None:
        out[name] = obj[()].tobytes() if isinstance(obj, h5py.Dataset) and obj.dtype.kind == "f" else (
            obj[()].tolist() if isinstance(obj, h5py.Dataset) else None)
        out.update({f"{name}@{k}": str(v) for k, v in obj.attrs.items()})

    with h5py.File(path, "r") as f:
        f.visititems(visit)
        out.update({f"@{k}": str(v) for k, v in f.attrs.items()})
    return out


def test_generate_on_ray_writes_the_dataset_of_a_local_run(ray_instance, tmp_path):
    """``dlovr generate --cluster``: the trials and their re-simulation on Ray give the local run's
    dataset bit for bit (a one-second demonstration compiled, one perturbed episode: the suite's
    time is short), and its temporary recordings beside the output are gone."""
    from dlovr.datasets import ExportOptions
    from dlovr.datasets.generate import generate, trial_setup

    script = Path(__file__).parents[1] / "data" / "touch_press.script.toml"
    assert cli("record", "--script", script, "-o", tmp_path / "touch.mcap").exit_code == 0
    assert cli("compile", tmp_path / "touch.mcap", "-o", tmp_path).exit_code == 0
    program, vary = tmp_path / "touch.program.json", ("--vary", "dlo.length=5%")
    here, out = tmp_path / "here.hdf5", tmp_path / "ray" / "gen.hdf5"
    out.parent.mkdir()
    setup = trial_setup(str(program), vary[1::2], 3)
    local = generate(setup, 1, here, ExportOptions(fmt="robomimic", fps=10))
    assert local.kept, "no successful trial to compare"
    r = cli("generate", program, "--episodes", 1, "--seed", 3, *vary, "--format", "robomimic", "-o", out,
            "--fps", 10, "--cluster", "local", "--workers", 2)
    assert r.exit_code == 0, r.output
    assert "kept 1 of 1 runs" in r.output
    assert _hdf5_items(out) == _hdf5_items(here)
    assert [p.name for p in out.parent.iterdir()] == ["gen.hdf5"]


HEAD = """
import sys
import ray
from ray._private.state import jobs
ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
print(ray.get_runtime_context().gcs_address, flush=True)
sys.stdin.read()  # until the test closes it
print(*sorted({int(j["DriverPid"]) for j in jobs()}), flush=True)  # the drivers that joined
ray.shutdown()
"""


@pytest.mark.slow
def test_compile_joins_a_running_cluster_at_its_address(tmp_path):
    """``--cluster HOST:PORT`` joins a cluster started elsewhere (here: another process, with token
    authentication as Ray sets it up by default, the token given to both as docs/scaling.md says): the
    cluster saw dlovr's driver, and the programs are those of local processes."""
    import secrets
    import subprocess
    import threading

    root = Path(dlovr.__file__).parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]),
           "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
    env.pop("RAY_ADDRESS", None)
    pipe = {"stdin": subprocess.PIPE, "stdout": subprocess.PIPE, "text": True, "env": env}
    head = subprocess.Popen([sys.executable, "-c", HEAD], **pipe)
    watchdog = threading.Timer(240, head.kill)
    watchdog.start()
    client = None
    try:
        address = head.stdout.readline().strip()
        assert address.rpartition(":")[2].isdigit(), address
        recs = [str(RECORDINGS / "table.mcap"), str(RECORDINGS / "edges.mcap")]
        cmd = [sys.executable, "-m", "dlovr", "compile", *recs, "-o", str(tmp_path / "ray")]
        client = subprocess.Popen([*cmd, "--cluster", address], **pipe, stderr=subprocess.STDOUT)
        out, _ = client.communicate(timeout=180)
        drivers, _ = head.communicate("", timeout=60)
    finally:
        watchdog.cancel()
        for proc in (head, client):
            if proc is not None:
                proc.kill()
    assert client.returncode == 0 and "2 compiled, 0 failed, 0 retried" in out, out
    assert client.pid in {int(pid) for pid in drivers.split()}, drivers  # it ran on that cluster
    assert cli("compile", *recs, "-o", tmp_path / "local").exit_code == 0
    for name in ("table.program.json", "edges.program.json"):
        assert (tmp_path / "ray" / name).read_bytes() == (tmp_path / "local" / name).read_bytes()


def test_compile_on_ray_writes_the_same_programs_as_local_processes(ray_instance, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    names = sorted(p.name for p in RECORDINGS.glob("*.mcap"))
    assert len(names) >= 4
    for n in names:
        shutil.copy(RECORDINGS / n, src / n)
    (src / "broken.mcap").write_bytes(b"not an mcap file")
    local = cli("compile", src, "-o", tmp_path / "local", "--workers", "2")
    on_ray = cli("compile", src, "-o", tmp_path / "ray", "--cluster", "local")
    for r in (local, on_ray):
        assert r.exit_code == 2, r.output  # any recording failed
        assert f"{len(names)} compiled, 1 failed, 0 retried" in r.output and "broken.mcap" in r.output
    for n in names:
        for ext in (".program.json", ".program.txt"):
            out = Path(n).stem + ext
            assert (tmp_path / "ray" / out).read_bytes() == (tmp_path / "local" / out).read_bytes()


def test_network_on_ray_and_local_processes_equals_reading_one_after_the_other(ray_instance, tmp_path):
    """``dlovr network --workers/--cluster`` reads the recordings elsewhere and builds the same network."""
    src = tmp_path / "in"
    src.mkdir()
    for k in range(3):  # three demonstrations of one scene
        shutil.copy(RECORDINGS / "table.mcap", src / f"table_{k}.mcap")
    outs = {}
    for name, extra in (("here", ()), ("local", ("--workers", "2")), ("ray", ("--cluster", "local"))):
        r = cli("network", src, "-o", tmp_path / f"{name}.json", *extra)
        assert r.exit_code == 0, r.output
        outs[name] = (tmp_path / f"{name}.json").read_text()
    assert outs["local"] == outs["here"] and outs["ray"] == outs["here"]
    # a broken recording is one line naming it, whichever engine read it
    (src / "broken.mcap").write_bytes(b"not an mcap file")
    r = cli("network", src, "-o", tmp_path / "x.json", "--workers", "2")
    assert r.exit_code == 2 and "broken.mcap" in r.output and "Traceback" not in r.output


def test_network_progress_counts_each_recording_as_it_completes(monkeypatch):
    """The progress bar of ``dlovr network --workers/--cluster`` moves as each recording is read (order
    of completion), not all at once after the batch."""
    import dlovr.batch
    from dlovr.recording.demonstrations import network_from_recordings

    events: list[tuple[str, int]] = []
    real = dlovr.batch.run_batch

    def logged(*args, **kwargs):
        for r in real(*args, **kwargs):
            events.append(("done", r.index))
            yield r

    monkeypatch.setattr(dlovr.batch, "run_batch", logged)
    paths = [RECORDINGS / "table.mcap"] * 3
    network_from_recordings(paths, progress=lambda k: events.append(("progress", k)), workers=2)
    assert [e for e in events if e[0] == "progress"] == [("progress", 1), ("progress", 2), ("progress", 3)]
    assert [e[0] for e in events] == ["done", "progress"] * 3


def _touch_program(d: Path) -> Path:
    """A 0.9 s demonstration on the table (lower the cable onto it), recorded and compiled."""
    from dlovr.recording import DemoRecorder, compile_recording
    from dlovr.scene import load_scene
    from dlovr.script import load_script
    from dlovr.sim import Simulator

    scene = load_scene("table")
    sim = Simulator(scene, track=True)
    with DemoRecorder(d / "touch.mcap", scene, sim, sim.tracker) as rec:
        for r in sim.run(load_script(Path(__file__).parents[1] / "data" / "touch_press.script.toml")):
            rec.step(r)
    path = d / "touch.program.json"
    path.write_text(compile_recording(d / "touch.mcap").dumps())
    return path


def _outcomes(d: Path) -> list[dict]:
    import json

    out = []
    for p in sorted(d.glob("trial_*.json")):
        t = json.loads(p.read_text())
        t.pop("wall_time")
        for k in ("program", "openloop"):
            t[k].pop("wall_time")
        out.append(t)
    return out


def _killing(monkeypatch, tmp_path: Path, modes: dict[int, str]) -> None:
    """Make every batch kill the worker of task ``i`` with SIGKILL (``modes[i]``: "once" or "always")."""
    import dlovr.batch

    real = dlovr.batch.run_batch

    def run_batch_killing(fn, tasks, **kwargs):
        tasks = [Task(t.key, (fn, modes.get(i, ""), str(tmp_path / f"killed{i}"), *t.args), t.kwargs)
                 for i, t in enumerate(tasks)]
        return real(call_or_die, tasks, **kwargs)

    monkeypatch.setattr(dlovr.batch, "run_batch", run_batch_killing)


@pytest.mark.slow
def test_run_and_record_trials_count_retried_and_lost_trials(monkeypatch, tmp_path):
    """A trial whose worker is killed once runs again; one killed on every attempt is a failed trial;
    ``run --trials`` and ``record --trials`` say how many of each (summary.json, demos.json, stdout)."""
    import json

    prog = _touch_program(tmp_path)
    _killing(monkeypatch, tmp_path, {1: "once", 2: "always"})
    r = cli("run", prog, "--scene", "table", "--trials", "3", "--seed", "5", "--vary", "dlo.length=5%",
            "--workers", "2", "-o", tmp_path / "trials")
    assert r.exit_code == 0, r.output
    assert "2 trials retried (a worker died), 1 lost" in r.output
    summary = json.loads((tmp_path / "trials" / "summary.json").read_text())
    assert summary["retried_trials"] == 2 and summary["lost_trials"] == 1
    lost = json.loads((tmp_path / "trials" / "trial_002.json").read_text())
    assert lost["program"]["reason"].startswith("trial lost:") and "SIGKILL" in lost["program"]["reason"]
    assert json.loads((tmp_path / "trials" / "trial_001.json").read_text())["attempts"] == 2

    for k in (1, 2):
        (tmp_path / f"killed{k}").unlink()
    script = Path(__file__).parents[1] / "data" / "touch_press.script.toml"
    r = cli("record", "--script", script, "--trials", "3", "--seed", "3", "--vary", "dlo.young=0.5..2",
            "--workers", "2", "-o", tmp_path / "demos")
    assert r.exit_code == 1 and "1 diverged or failed, 2 retried" in r.output, r.output
    demos = json.loads((tmp_path / "demos" / "demos.json").read_text())["demonstrations"]
    assert [d["attempts"] for d in demos] == [1, 2, 3] and demos[2]["path"] is None
    assert (tmp_path / "demos" / "demo_001.mcap").is_file()


def test_run_trials_on_ray_give_the_same_outcomes_as_local_processes(ray_instance, tmp_path):
    prog = _touch_program(tmp_path)
    args = ["run", prog, "--scene", "table", "--trials", "3", "--seed", "5", "--baseline", "replay",
            "--vary", "dlo.length=10%", "--vary", "objects.pos=0.004"]
    local = cli(*args, "--workers", "2", "-o", tmp_path / "local")
    on_ray = cli(*args, "--cluster", "local", "-o", tmp_path / "ray")
    assert local.exit_code == 0 and on_ray.exit_code == 0, local.output + on_ray.output
    a, b = _outcomes(tmp_path / "local"), _outcomes(tmp_path / "ray")
    assert len(a) == 3 and a == b
    assert cli("run", prog, "--cluster", "local").exit_code == 2  # --cluster needs --trials


def test_record_trials_on_ray_record_the_same_demonstrations(ray_instance, tmp_path):
    from dlovr.recording import Recording

    script = Path(__file__).parents[1] / "data" / "touch_press.script.toml"
    args = ["record", "--script", script, "--trials", "2", "--seed", "3", "--vary", "dlo.young=0.5..2"]
    assert cli(*args, "-o", tmp_path / "local").exit_code == 0
    r = cli(*args, "--cluster", "local", "-o", tmp_path / "ray")
    assert r.exit_code == 0, r.output
    for name in ("demo_000.mcap", "demo_001.mcap"):
        assert Recording(tmp_path / "ray" / name).states() == Recording(tmp_path / "local" / name).states()
