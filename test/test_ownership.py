"""One owner, one rule: no module reads or writes another object's private attribute (``x._name``
where ``x`` is not ``self``, ``cls`` or ``super()``, nor a parameter annotated with the method's own
class).

Tests' exceptions are listed per file, by attribute name and count: a ratchet. The test fails
when a new one appears and when a listed one disappears (then shrink the list); tests may read
the state of the module they test.
"""

from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PUBLIC = {"_exit"}
"""Underscore names that are public API (``os._exit``)."""

PACKAGE_ALLOWED: dict[str, dict[str, int]] = {}
TEST_ALLOWED: dict[str, dict[str, int]] = {
    "test/test_batch.py": {"_compiled_step": 1, "_kernels": 1, "_last": 2, "_mem": 2},
    "test/test_docs.py": {"_actions": 2},
    "test/test_imu.py": {"_rate_hz": 1},
    "test/test_kernels.py": {"_YamlDumper": 1, "_library_from_doc": 1, "_read_yaml": 1, "_read_yaml_with_rows": 1,
                             "_yaml_header": 1},
    "test/test_matcher.py": {"_compiled_step": 1, "_e": 2, "_kernels": 2, "_lam": 1, "_mu_seg": 2,
                             "_row_shift_means": 2, "_state": 1, "_step_state": 4, "_valid": 2},
    "test/test_supervisor.py": {"_mem": 2},
}


class _Reaches(ast.NodeVisitor):
    """Counts ``x._name`` by name, outside ``self``/``cls`` and same-class parameters."""

    def __init__(self) -> None:
        self.found: Counter[str] = Counter()
        self.classes: list[str] = []
        self.own: list[set[str]] = [set()]

    def visit_ClassDef(self, node: ast.ClassDef) -> None:
        self.classes.append(node.name)
        self.generic_visit(node)
        self.classes.pop()

    def visit_FunctionDef(self, node: ast.FunctionDef | ast.AsyncFunctionDef) -> None:
        a = node.args
        same = {p.arg for p in [*a.posonlyargs, *a.args, *a.kwonlyargs]
                if self.classes and p.annotation is not None and ast.unparse(p.annotation).strip("'\"") == self.classes[-1]}
        self.own.append({"self", "cls"} | same)
        self.generic_visit(node)
        self.own.pop()

    visit_AsyncFunctionDef = visit_FunctionDef

    def visit_Attribute(self, node: ast.Attribute) -> None:
        name = node.attr
        if name.startswith("_") and not name.startswith("__") and name not in PUBLIC and not (
                isinstance(node.value, ast.Name) and node.value.id in (self.own[-1] | {"self", "cls"})) and not (
                isinstance(node.value, ast.Call) and ast.unparse(node.value.func) == "super"):
            self.found[name] += 1
        self.generic_visit(node)


def _reaches(folder: str) -> dict[str, dict[str, int]]:
    out = {}
    for path in sorted((ROOT / folder).rglob("*.py")):
        visitor = _Reaches()
        visitor.visit(ast.parse(path.read_text(encoding="utf-8")))
        if visitor.found:
            out[path.relative_to(ROOT).as_posix()] = dict(sorted(visitor.found.items()))
    return out


def test_no_module_reaches_into_another_objects_state() -> None:
    assert _reaches("gait_estimator") == PACKAGE_ALLOWED


def test_tests_reach_into_no_more_state_than_today() -> None:
    assert _reaches("test") == TEST_ALLOWED


def test_the_check_finds_a_reach() -> None:
    visitor = _Reaches()
    visitor.visit(ast.parse(
        "class A:\n"
        "    def f(self, other: A, b: B):\n"
        "        self._x = other._y + b._z + cls_of(self)._w\n"
        "def g(node):\n"
        "    node._count += 1\n"
    ))
    assert visitor.found == {"_z": 1, "_w": 1, "_count": 1}
