"""The model code is pure: importing it loads neither MuJoCo nor viser (brief, engineering standards)."""

from __future__ import annotations

import subprocess
import sys

import pytest

PURE = ["dlovr.topology", "dlovr.discrete", "dlovr.transitions", "dlovr.program"]


@pytest.mark.parametrize("module", PURE)
def test_model_module_imports_no_simulator_or_ui(module):
    code = f"import sys, {module}; print(','.join(m for m in ('mujoco', 'viser') if m in sys.modules))"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.strip()
    assert out == "", f"{module} imports {out}"
