"""The layering of the package (see gait_estimator/__init__.py and docs/architecture.md):
core -> io -> analysis -> ros -> dashboard -> cli, a subpackage importing only those to its left; only
``ros`` imports rclpy or ROS message packages; no import cycles between modules."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "gait_estimator"
LAYERS = ("core", "io", "analysis", "ros", "dashboard", "cli")
ROS_MODULES = ("rclpy", "builtin_interfaces", "diagnostic_msgs", "rcl_interfaces", "rosgraph_msgs", "sensor_msgs",
               "std_msgs", "std_srvs", "ament_index_python")


def _modules() -> dict[str, Path]:
    return {".".join(p.relative_to(PKG.parent).with_suffix("").parts): p for p in PKG.rglob("*.py")}


def _imports(name: str, path: Path) -> list[tuple[str, int]]:
    """Absolute names imported by module ``name`` (anywhere in the file, lazy imports included)."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.append((mod, node.lineno))
            out += [(f"{mod}.{a.name}", node.lineno) for a in node.names if f"{mod}.{a.name}" in _modules()]
    return out


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "gait_estimator" and parts[1] in LAYERS else None


def test_every_module_lives_in_a_layer() -> None:
    loose = [m for m in _modules() if m.count(".") == 1 and not m.endswith("__init__")]
    assert loose == [], "modules outside core/io/analysis/ros/dashboard/cli"


@pytest.mark.parametrize("layer", LAYERS)
def test_layers_import_only_lower_layers(layer: str) -> None:
    allowed = set(LAYERS[: LAYERS.index(layer) + 1])
    bad = []
    for name, path in _modules().items():
        if _layer(name) != layer:
            continue
        for mod, line in _imports(name, path):
            target = _layer(mod)
            if target is not None and target not in allowed:
                bad.append(f"{path.relative_to(PKG.parent)}:{line} imports {mod}")
    assert bad == []


def test_only_ros_imports_rclpy_and_messages() -> None:
    bad = []
    for name, path in _modules().items():
        if _layer(name) == "ros":
            continue
        for mod, line in _imports(name, path):
            if mod.split(".")[0] in ROS_MODULES and not (name.endswith("io.resources") and mod.startswith("ament_index")):
                bad.append(f"{path.relative_to(PKG.parent)}:{line} imports {mod}")
    assert bad == []


def test_no_import_cycles_between_modules() -> None:
    mods = _modules()
    graph = {n: {m for m, _ in _imports(n, p) if m in mods and m != n and not m.endswith("__init__")} for n, p in mods.items()}
    graph = {n: {m for m in deps if not mods[m].name == "__init__.py"} for n, deps in graph.items()}
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(n: str, stack: list[str]) -> None:
        state[n] = 1
        for m in sorted(graph[n]):
            if state.get(m) == 1:
                cycles.append([*stack[stack.index(m):], m])
            elif m not in state:
                visit(m, [*stack, m])
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [n])
    assert cycles == []


OPTIONAL = ("scipy", "matplotlib", "rosbags", "numba", "aiohttp")
"""Optional packages (setup.py extras): imported inside the functions that need them, so that the
estimator and ``process`` run with numpy and PyYAML only (test_public_api.py runs that)."""
TOP_LEVEL_OPTIONAL = {"gait_estimator.core.compiled": "numba", "gait_estimator.analysis.plots": "matplotlib",
                      "gait_estimator.dashboard.server": "aiohttp"}
"""Where a top-level import is fine: guarded (compiled: numba optional) or imported lazily itself
(plots, by ``evaluate`` only; the dashboard's server, by the ``dashboard`` command only)."""


def test_optional_packages_are_imported_where_used() -> None:
    bad = []
    for name, path in _modules().items():
        for node in ast.parse(path.read_text(encoding="utf-8")).body:  # module level only
            if isinstance(node, ast.Try):
                continue  # a guarded import
            mods = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for mod in mods:
                root = mod.split(".")[0]
                if root in OPTIONAL and TOP_LEVEL_OPTIONAL.get(name) != root:
                    bad.append(f"{path.relative_to(PKG.parent)}:{node.lineno} imports {mod}")
    assert bad == []


MAX_MODULE_LINES = 550
MAX_FUNCTION_LINES = 90
SIZE_EXCEPTIONS = {"gait_estimator.core.compiled.step_rows", "gait_estimator.core.compiled.step_rows_parallel"}
"""The compiled kernel (one pass per step, by design)."""


def test_modules_and_functions_stay_small() -> None:
    """Modules <= ~500 lines, functions <= ~80 (docs/architecture.md), with a little slack."""
    bad = []
    for name, path in _modules().items():
        text = path.read_text(encoding="utf-8")
        if text.count("\n") > MAX_MODULE_LINES and name not in SIZE_EXCEPTIONS:
            bad.append(f"{name}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and f"{name}.{node.name}" not in SIZE_EXCEPTIONS:
                length = (node.end_lineno or node.lineno) - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    bad.append(f"{name}.{node.name}: {length} lines")
    assert bad == []


def test_offline_commands_import_without_ros() -> None:
    """The ROS-free layers and the CLI import with rclpy and every message package unavailable."""
    code = (
        "import sys\n"
        f"for m in {ROS_MODULES!r}: sys.modules[m] = None\n"
        "import gait_estimator, gait_estimator.cli.app as c\n"
        "import gait_estimator.core.estimator, gait_estimator.io.bag, gait_estimator.io.bag_write\n"
        "import gait_estimator.analysis.train, gait_estimator.analysis.evaluate, gait_estimator.analysis.plots\n"
        "c.build_parser()\n"
        "print('ok')\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr
