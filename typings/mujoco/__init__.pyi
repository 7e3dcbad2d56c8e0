# Type stub for pyright ([tool.pyright] in pyproject.toml): mujoco ships its bindings as compiled modules
# (_structs, _functions, _enums, _specs ...) without .pyi stubs, so a type checker cannot see the names
# `mujoco/__init__.py` star-imports from them (MjModel, MjData, MjSpec, mj_step, mjtObj ...). Every name
# of the module is therefore typed Any here; the library's own behaviour is untouched.
from typing import Any

def __getattr__(name: str) -> Any: ...
