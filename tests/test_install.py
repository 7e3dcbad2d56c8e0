"""A non-editable install has everything: the wheel carries the built-in scenes, scripts and meshes
(in ``dlovr/_scenes``).

The wheel is built from a copy of the package's sources (``--no-build-isolation --no-index``: the
test environment's setuptools and wheel, no network), installed into a fresh virtual environment
that borrows this one's dependencies (a ``.pth`` line, not this checkout), and ``dlovr scenes``,
``dlovr scene show`` and ``dlovr demo`` run there from a folder outside the repository.

The installed package takes this checkout's compiled kernels from the kernel store
(:func:`dlovr.jit.keep_in_store`: the same sources, Python and numba) instead of compiling them again
(30-40 s), and says nothing about compiling.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SOURCES = ("pyproject.toml", "setup.py", "README.md", "dlovr", "scenes")


def run(cmd: list[str], cwd: Path, env: dict[str, str], timeout: float = 120) -> str:
    return run_both(cmd, cwd, env, timeout).stdout


def run_both(
    cmd: list[str], cwd: Path, env: dict[str, str], timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    r = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, f"{' '.join(map(str, cmd))}\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}"
    return r


@pytest.mark.slow
def test_the_wheel_ships_the_scenes_and_runs_a_demo(tmp_path):
    from dlovr.jit import store_dir
    from dlovr.sim.warmup import NOTICE, warm_up

    warm_up()  # this checkout's kernels (compiled now if they were not) into the kernel store
    assert store_dir() is not None and store_dir().is_dir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    src = tmp_path / "src"
    for name in SOURCES:
        p = ROOT / name
        if p.is_dir():
            shutil.copytree(p, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            src.mkdir(exist_ok=True)
            shutil.copy2(p, src / name)
    dist = tmp_path / "dist"
    run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "--no-index",
         str(src), "-w", str(dist)],
        tmp_path, env, timeout=300,
    )
    (wheel,) = dist.glob("dlovr-*.whl")

    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp_path, env)
    py = venv / "bin" / "python"
    purelib = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    site = Path(run([str(py), "-c", purelib], tmp_path, env).strip())
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (site / "borrowed-dependencies.pth").write_text("".join(f"{d}\n" for d in sorted(deps)))
    run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)], tmp_path, env)

    work = tmp_path / "elsewhere"  # no scenes/ folder around
    work.mkdir()
    where = run(
        [str(py), "-c", "import dlovr, dlovr.scene; print(dlovr.__file__); print(dlovr.scene.scenes_dir())"],
        work, env,
    ).split()
    assert all(Path(w).is_relative_to(venv) for w in where), where
    dlovr = str(venv / "bin" / "dlovr")
    listed = run([dlovr, "scenes"], work, env)
    names = {line.split()[0] for line in listed.splitlines()}
    assert {"table", "peg_in_hole", "edges", "l_block", "corners"} <= names, listed
    shown = run([dlovr, "scene", "show", "l_block"], work, env)
    assert "object lblock" in shown  # its mesh shipped too
    table = run_both([dlovr, "demo", "--scene", "table"], work, env, timeout=300)  # the built-in script
    assert "V/F[table.F1]" in table.stdout
    assert NOTICE not in table.stderr  # the kernels came from the store
