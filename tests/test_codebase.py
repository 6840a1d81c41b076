"""The shape of the code itself: modules small enough to read in one sitting,
and test modules that share helpers through support modules, not through each
other (a test module imported by another runs its tests' imports twice and
ties two files' private details together)."""

from __future__ import annotations

import ast
from pathlib import Path

from conftest import ROOT

MAX_LINES = 600
TESTS = ROOT / "tests"


def test_no_source_module_is_over_the_limit() -> None:
    long = {
        path.relative_to(ROOT).as_posix(): n
        for path in sorted((ROOT / "src" / "virf").rglob("*.py"))
        if (n := len(path.read_text(encoding="utf-8").splitlines())) > MAX_LINES
    }
    assert long == {}, f"split these modules along their seams (limit {MAX_LINES} lines)"


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_test_modules_import_support_modules_only() -> None:
    test_modules = {p.stem for p in TESTS.glob("test_*.py")}
    crossing = {
        path.name: sorted(imported_modules(path) & test_modules)
        for path in sorted(TESTS.glob("*.py"))
        if imported_modules(path) & test_modules
    }
    assert crossing == {}, "move shared helpers into a *_support.py module"


def test_the_check_sees_an_import_between_test_modules(tmp_path: Path) -> None:
    sample = tmp_path / "test_sample.py"
    sample.write_text("import os\nfrom test_loop import CLOSES\n", encoding="utf-8")
    assert "test_loop" in imported_modules(sample)
