"""The package layout holds: the model is pure, dlovr's modules import each other without cycles, every
module has its layer and imports only downwards, and no function or class outgrows a reader
(docs/architecture.md, "Layout")."""

from __future__ import annotations

import ast
import functools
import pkgutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

import dlovr
import dlovr.model

ROOT = Path(dlovr.__file__).parent
FORBIDDEN_IN_MODEL = ("mujoco", "viser", "trimesh", "mcap", "manifold3d", "coacd", "numba")
MAX_MODULE_LINES = 1000  # generous: a file is split by concept, not by line count (see MAX_FUNCTION_LINES)
MAX_CLASS_LINES = 320
MAX_FUNCTION_LINES = 80  # the rule: a function a reader takes in at once (aim for < 60)


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


def _imports(name: str, path: Path, modules: dict[str, Path], type_only: bool = False) -> set[str]:
    """dlovr modules that ``name`` imports anywhere in its file (function-level imports included,
    ``if TYPE_CHECKING:`` blocks only with ``type_only``); importing ``a.b.c`` also runs ``a.b``'s
    ``__init__``."""
    tree = ast.parse(path.read_text(), str(path))
    parents = {c: p for p in ast.walk(tree) for c in ast.iter_child_nodes(p)}
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets: set[str] = set()
    for node in ast.walk(tree):
        if not isinstance(node, ast.Import | ast.ImportFrom):
            continue
        if not type_only and _in_type_checking(node, parents):
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


@functools.cache
def import_graph(type_only: bool = False) -> dict[str, set[str]]:
    """Module -> the dlovr modules it imports (``if TYPE_CHECKING:`` imports too with ``type_only``)."""
    modules = _modules()
    return {name: _imports(name, path, modules, type_only) for name, path in modules.items()}


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


def test_no_import_cycles_counting_type_only_imports():
    """No circle at all: an ``if TYPE_CHECKING:`` import is a dependency of the source too."""
    cycle = find_cycle(import_graph(type_only=True))
    assert cycle is None, "import cycle (type-only imports counted): " + " -> ".join(cycle)


def test_import_finder_sees_function_level_and_type_only_imports(tmp_path):
    pkg = tmp_path / "dlovr"
    pkg.mkdir()
    for m in ("a", "b", "c"):
        (pkg / f"{m}.py").write_text("")
    f = pkg / "m.py"
    f.write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from dlovr.a import X\n"
        "def f():\n    from dlovr import b\n    import dlovr.c\n"
    )
    modules = {f"dlovr.{m}": pkg / f"{m}.py" for m in ("a", "b", "c", "m")}
    assert _imports("dlovr.m", f, modules) == {"dlovr.b", "dlovr.c"}
    assert _imports("dlovr.m", f, modules, type_only=True) == {"dlovr.a", "dlovr.b", "dlovr.c"}


def test_ui_modules_import_each_other_without_a_circle_counting_type_only_imports():
    """The browser UI's panels, viewport and loop see the server through ``dlovr.ui.app`` only: no
    circle among the UI's modules, ``if TYPE_CHECKING:`` imports counted too."""
    graph = import_graph(type_only=True)
    ui = {n: {d for d in deps if d.startswith("dlovr.ui")} for n, deps in graph.items() if "dlovr.ui" in n}
    cycle = find_cycle(ui)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)
    below = {n for n, deps in ui.items() if "dlovr.ui.server" in deps} - {"dlovr.ui"}
    assert not below, f"modules that import the server: {sorted(below)}"


def test_ui_modules_touch_no_private_attribute_of_the_app():
    """No UI module but the server reads or writes ``app._x`` (the narrow interface is
    :class:`dlovr.ui.app.App`)."""
    bad = []
    for name, path in _modules().items():
        if not name.startswith("dlovr.ui") or name == "dlovr.ui.server":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.Attribute) or not node.attr.startswith("_") or node.attr[:2] == "__":
                continue
            owner = ast.unparse(node.value)
            if owner == "app" or owner.endswith(".app"):
                bad.append(f"{name}: {ast.unparse(node)}")
    assert not bad, "private attributes of the app: " + "; ".join(bad)


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


@pytest.mark.slow
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


# The data flow of docs/architecture.md: each package imports only the ones below it, ``cli`` is on
# top, and ``batch`` imports no other dlovr module but the input layer's base (its error type).
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
            top = here == "dlovr.cli" or name == "dlovr.__main__"
            if there == "dlovr.cli" and not top:
                upward.append(f"{name} -> {d}")
            if here == "dlovr.batch" and there not in BATCH_MAY_IMPORT:
                upward.append(f"{name} -> {d}")
    assert not upward, "imports against the data flow of docs/architecture.md: " + "; ".join(sorted(upward))


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


# Functions allowed over MAX_FUNCTION_LINES, each with its reason. An entry that no longer needs to be one
# fails the test too, so the list only shrinks.
#: Names of vector helpers (with or without leading underscores): ``dlovr.transforms`` has them.
_VECTOR_HELPERS = ("unit", "units", "norm", "dot", "angle", "angle_deg", "normalize", "normalise")


def test_vector_helpers_live_in_transforms_only():
    """Dot products, lengths, unit vectors and angles: one place, ``dlovr/transforms.py``, with one
    zero-vector rule (a module-level function of such a name anywhere else is a second copy, likely
    with a rule of its own). The compiled kernels' ``dot3``/``norm3`` (numba, scalar arguments,
    rounded as the numpy code they replaced) are kernel arithmetic, not copies."""
    elsewhere = []
    for name, path in _modules().items():
        if name == "dlovr.transforms":
            continue
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.FunctionDef) and node.name.lstrip("_").lower() in _VECTOR_HELPERS:
                elsewhere.append(f"{name}.{node.name}")
    assert not elsewhere, f"vector helpers outside dlovr.transforms: {elsewhere}"


LONG_FUNCTIONS = {
    "dlovr.geometry.kernels.classify_point": "a numba kernel: one compiled loop over the packed pieces",
    "dlovr.geometry.kernels.pair_hits": "a numba kernel: one compiled loop over the packed pieces",
    "dlovr.sim.kernels.step_record": "a numba kernel: the whole per-step record in one compiled call",
    "dlovr.sim.track_kernels.track_step": "a numba kernel: the tracker's per-step path in one compiled call",
}


def _functions(tree: ast.Module, prefix: str) -> Iterator[tuple[str, int]]:
    """Every function (methods and nested functions too) as (qualified name, lines from ``def`` to its
    last line)."""

    def walk(node: ast.AST, scope: str) -> Iterator[tuple[str, int]]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                name = f"{scope}.{child.name}"
                yield name, (child.end_lineno or child.lineno) - child.lineno + 1
                yield from walk(child, name)
            elif isinstance(child, ast.ClassDef):
                yield from walk(child, f"{scope}.{child.name}")
            else:
                yield from walk(child, scope)

    return walk(tree, prefix)


def test_function_finder_sees_methods_and_nested_functions():
    source = "def f():\n    def g():\n        pass\n\nclass C:\n    async def h(self):\n        pass\n"
    tree = ast.parse(source)
    assert dict(_functions(tree, "m")) == {"m.f": 3, "m.f.g": 2, "m.C.h": 2}


def test_functions_stay_short():
    sizes = {}
    for name, path in _modules().items():
        sizes.update(_functions(ast.parse(path.read_text()), name))
    long = {q: n for q, n in sizes.items() if n > MAX_FUNCTION_LINES and q not in LONG_FUNCTIONS}
    too_long = sorted(f"{q}: {n} lines" for q, n in long.items())
    stale = sorted(q for q in LONG_FUNCTIONS if sizes.get(q, 0) <= MAX_FUNCTION_LINES)
    assert not too_long, f"functions over {MAX_FUNCTION_LINES} lines: " + "; ".join(too_long)
    assert not stale, f"LONG_FUNCTIONS names functions that are gone or short now: {stale}"


# Every top-level module and package of dlovr in its layer, lowest first: a module imports only modules
# of its own layer or below (function-level and ``if TYPE_CHECKING:`` imports counted).
BASE, MODEL, FORMATS, GEOMETRY, SIM, RECORDING, EXECUTION, UI, CLI = range(9)
MODULE_LAYERS = {
    "dlovr.transforms": BASE,  # pure: quaternions, rotations, vectors
    "dlovr.inputs": BASE,  # pure: the one input error and field checks
    "dlovr.cache": BASE,  # the user cache directory
    "dlovr.jit": BASE,  # numba setup
    "dlovr.outputs": BASE,  # safe output files
    "dlovr.signals": BASE,  # SIGINT/SIGTERM at any moment: the pending signal
    "dlovr.batch": BASE,  # batch work: imports no other dlovr module but inputs (its error type)
    "dlovr.plausibility": BASE,  # numpy: penetration and point speed of simulation steps, bounds
    "dlovr.model": MODEL,
    "dlovr.scene": FORMATS,  # scene files
    "dlovr.script": FORMATS,  # scripted demonstrations
    "dlovr.facts": FORMATS,  # --facts files
    "dlovr.geometry": GEOMETRY,
    "dlovr.sim": SIM,
    "dlovr.recording": RECORDING,
    "dlovr.execution": EXECUTION,
    "dlovr.datasets": EXECUTION,  # learning datasets: replays recordings, runs trials (imports execution)
    "dlovr.ui": UI,
    "dlovr.cli": CLI,
    "dlovr.__main__": CLI,
}


#: What dlovr.batch may import of dlovr: its own modules, the input error, the pending signal.
BATCH_MAY_IMPORT = ("dlovr.batch", "dlovr.inputs", "dlovr.signals")


def _top(module: str) -> str:
    return ".".join(module.split(".")[:2])


def _top_level_modules() -> set[str]:
    """dlovr's top-level modules (``dlovr/*.py``) and packages (``dlovr/*/__init__.py``)."""
    names = {f"dlovr.{p.stem}" for p in ROOT.glob("*.py") if p.name != "__init__.py"}
    return names | {f"dlovr.{p.parent.name}" for p in ROOT.glob("*/__init__.py")}


def test_every_top_level_module_has_a_layer():
    unknown = sorted(_top_level_modules() - set(MODULE_LAYERS))
    assert not unknown, f"top-level modules without a layer in MODULE_LAYERS: {unknown}"


def test_every_module_imports_only_its_layer_and_below():
    upward = []
    for name, deps in import_graph(type_only=True).items():
        here = MODULE_LAYERS.get(_top(name))
        for d in deps:
            there = MODULE_LAYERS.get(_top(d))
            if here is not None and there is not None and there > here:
                upward.append(f"{name} -> {d}")
            if _top(name) == "dlovr.batch" and _top(d) not in BATCH_MAY_IMPORT:
                upward.append(f"{name} -> {d} (batch imports no other dlovr module)")
    assert not upward, "imports against the layers: " + "; ".join(sorted(upward))
