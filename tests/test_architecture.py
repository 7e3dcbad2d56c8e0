"""The package layout holds: the model is pure, dlovr's modules import each other without cycles, and
no module or class outgrows a reader (README, "Layout")."""

from __future__ import annotations

import ast
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import dlovr
import dlovr.model

ROOT = Path(dlovr.__file__).parent
FORBIDDEN_IN_MODEL = ("mujoco", "viser", "trimesh", "mcap", "manifold3d", "coacd", "numba")
MAX_MODULE_LINES = 620
MAX_CLASS_LINES = 320


def _modules() -> dict[str, Path]:
    """Every module of dlovr: dotted name -> file (a package is its ``__init__.py``)."""
    out = {}
    for path in ROOT.rglob("*.py"):
        rel = path.relative_to(ROOT.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _in_type_checking(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> bool:
    while node in parents:
        node = parents[node]
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            return True
    return False


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """dlovr modules that ``name`` imports anywhere in its file (function-level imports included,
    ``if TYPE_CHECKING:`` blocks excluded); importing ``a.b.c`` also runs ``a.b``'s ``__init__``."""
    tree = ast.parse(path.read_text(), str(path))
    parents = {c: p for p in ast.walk(tree) for c in ast.iter_child_nodes(p)}
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets: set[str] = set()
    for node in ast.walk(tree):
        if _in_type_checking(node, parents):
            continue
        if isinstance(node, ast.Import):
            targets.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*up, base]).strip(".")
            targets.add(base)
            targets.update(f"{base}.{a.name}" for a in node.names)
    deps = set()
    for t in targets:
        parts = t.split(".")
        for k in range(2, len(parts) + 1):  # the module and every package on its way
            m = ".".join(parts[:k])
            if m in modules and m != name and not name.startswith(m + "."):
                deps.add(m)
    return deps


def import_graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as a list of modules (first == last), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return [*stack[stack.index(m) :], m]
            if m not in state and (c := visit(m)):
                return c
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state and (c := visit(n)):
            return c
    return None


def test_no_import_cycles():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_model_imports_only_model_and_transforms():
    graph = import_graph()
    for name, deps in graph.items():
        if name.startswith("dlovr.model"):
            allowed = ("dlovr", "dlovr.transforms", "dlovr.inputs")
            bad = {d for d in deps if not (d.startswith("dlovr.model") or d in allowed)}
            assert not bad, f"{name} imports {sorted(bad)}"


MODEL_MODULES = sorted(
    ["dlovr.model"] + [f"dlovr.model.{m.name}" for m in pkgutil.iter_modules(dlovr.model.__path__)]
)


@pytest.mark.parametrize("module", MODEL_MODULES)
def test_model_package_is_pure(module):
    names = repr(FORBIDDEN_IN_MODEL)
    code = f"import sys, {module}; print(','.join(m for m in {names} if m in sys.modules))"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    out = run.stdout.strip()
    assert out == "", f"{module} imports {out}"


def _third_party_imports(path: Path) -> set[str]:
    """Top-level names of every module ``path`` imports anywhere in its file (function-level imports and
    ``if TYPE_CHECKING:`` blocks included: the purity rule holds for the source, not only for one run)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_model_sources_name_no_forbidden_library():
    """Every file under dlovr/model/ (nested packages too), imports inside functions included."""
    files = sorted((ROOT / "model").rglob("*.py"))
    assert len(files) >= len(MODEL_MODULES)
    bad = {
        str(f.relative_to(ROOT)): sorted(_third_party_imports(f) & set(FORBIDDEN_IN_MODEL)) for f in files
    }
    bad = {k: v for k, v in bad.items() if v}
    assert not bad, f"dlovr/model imports {bad}"


def test_forbidden_import_finder_sees_function_level_imports(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("def f():\n    import mujoco.viewer\n    from trimesh import Trimesh\n")
    assert _third_party_imports(f) >= {"mujoco", "trimesh"}


def test_modules_and_classes_stay_small():
    too_long = []
    for name, path in _modules().items():
        text = path.read_text()
        n = text.count("\n")
        if n > MAX_MODULE_LINES:
            too_long.append(f"module {name}: {n} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef):
                size = (node.end_lineno or node.lineno) - node.lineno + 1
                if size > MAX_CLASS_LINES:
                    too_long.append(f"class {name}.{node.name}: {size} lines")
    assert not too_long, "; ".join(too_long)


# The README's data flow: each package imports only the ones below it, ``cli*`` is on top, and
# ``batch`` imports no other dlovr module.
LAYERS = ("dlovr.model", "dlovr.geometry", "dlovr.sim", "dlovr.recording", "dlovr.execution", "dlovr.ui")


def _package(module: str) -> str:
    return ".".join(module.split(".")[:2])


def test_packages_import_only_the_layers_below_them_and_cli_is_on_top():
    graph = import_graph()
    upward = []
    for name, deps in graph.items():
        here = _package(name)
        for d in deps:
            there = _package(d)
            if here in LAYERS and there in LAYERS and LAYERS.index(there) > LAYERS.index(here):
                upward.append(f"{name} -> {d}")
            top = here.startswith("dlovr.cli") or name.endswith(".cli") or name == "dlovr.__main__"
            if there.startswith("dlovr.cli") and not top:
                upward.append(f"{name} -> {d}")
            if here == "dlovr.batch" and there != "dlovr.batch":
                upward.append(f"{name} -> {d}")
    assert not upward, "imports against the README's data flow: " + "; ".join(sorted(upward))


def test_rotation_helpers_live_in_transforms_only():
    """Quaternions, rotation matrices and rotation vectors: one place, ``dlovr/transforms.py`` (a
    module-level function whose name speaks of them anywhere else is a second copy)."""
    words = ("quat", "rotvec", "slerp", "rotation", "matrix")
    elsewhere = []
    for name, path in _modules().items():
        if name == "dlovr.transforms":
            continue
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.FunctionDef) and any(w in node.name.lower() for w in words):
                elsewhere.append(f"{name}.{node.name}")
    assert not elsewhere, f"rotation helpers outside dlovr.transforms: {elsewhere}"
