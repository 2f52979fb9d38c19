"""No production function is 80 lines or longer (units a person can hold in mind), and no module
over 600 lines.

Parses every ``.py`` file of ``aerodaas/``, ``actors/``, ``schedulers/`` and ``clusters/`` with :mod:`ast` and
measures each function and method (nested ones too) from its ``def`` line to its last line, docstring and
comments included. The allow-list holds the functions still over the limit when this test was written, each
split by another engineer working in parallel (the end-of-run summary): it may only
shrink. An entry whose function is now under the limit (or gone) fails the test too, so the list is emptied
as the splits land.
"""
from __future__ import annotations

import ast
import functools
from pathlib import Path

from tests.architecture import sources

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("aerodaas", "actors", "schedulers", "clusters")
#: a function this long or longer fails
MAX_LINES = 80

#: (path relative to the repository root, qualified name) of today's remaining long functions, with who splits
#: them. Shrinking only: remove an entry once its function is split (the test says which ones are).
ALLOWED: dict[tuple[str, str], str] = {}


def _functions(tree: ast.AST, prefix: str = ""):
    """(qualified name, lines) of every function and method under ``tree``, nested ones included."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            name = prefix + node.name
            yield name, node.end_lineno - node.lineno + 1
            yield from _functions(node, name + ".")
        elif isinstance(node, ast.ClassDef):
            yield from _functions(node, prefix + node.name + ".")
        else:
            yield from _functions(node, prefix)


@functools.lru_cache(maxsize=1)
def _long_functions() -> dict[tuple[str, str], int]:
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            for name, lines in _functions(sources.tree(path)):
                if lines >= MAX_LINES:
                    out[(rel, name)] = lines
    return out


def test_no_function_is_80_lines_or_longer():
    long = _long_functions()
    new = {k: n for k, n in long.items() if k not in ALLOWED}
    assert not new, ("functions of 80 lines or longer (split them where their concepts end): "
                     + "; ".join(f"{p}:{q} ({n} lines)" for (p, q), n in sorted(new.items())))


def test_allow_list_only_shrinks():
    """Every allow-listed function is still long: a split one leaves the list."""
    long = _long_functions()
    done = sorted(k for k in ALLOWED if k not in long)
    assert not done, f"split (or gone): remove from ALLOWED: {done}"


def test_the_measure_counts_a_long_function():
    """The measure itself: an 80-line function is found, nested in a class, a 79-line one is not."""
    src = "class C:\n    def f(self):\n" + "        x = 1\n" * 79 + "    def g(self):\n" + "        y = 2\n" * 78
    found = dict(_functions(ast.parse(src)))
    assert found == {"C.f": 80, "C.g": 79}


#: a production module longer than this fails (the developers' guide: no module over 600 lines)
MAX_MODULE_LINES = 600


def _long_modules(root: Path = ROOT, limit: int = MAX_MODULE_LINES) -> dict[str, int]:
    """Line count of every ``.py`` module of :data:`PACKAGES` under ``root`` longer than ``limit``."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((root / pkg).rglob("*.py")):
            n = len(path.read_text(encoding="utf-8").splitlines())
            if n > limit:
                out[path.relative_to(root).as_posix()] = n
    return out


def test_no_module_is_over_600_lines():
    long = _long_modules()
    assert not long, ("modules over 600 lines (split them where their concepts end): "
                      + "; ".join(f"{p} ({n} lines)" for p, n in sorted(long.items())))


def test_the_module_measure_counts_a_long_module(tmp_path):
    """The measure itself: a 601-line module of a package is found, a 600-line one is not."""
    (tmp_path / "aerodaas").mkdir()
    (tmp_path / "aerodaas" / "long.py").write_text("x = 1\n" * 601)
    (tmp_path / "aerodaas" / "fits.py").write_text("x = 1\n" * 600)
    assert _long_modules(tmp_path) == {"aerodaas/long.py": 601}


def test_tests_are_laid_out_like_the_code():
    """Every test module sits in an area folder ``tests/<area>/`` (one per concept, with an
    ``__init__.py`` that says what the area tests), none directly under ``tests/``, and none over 600 lines: shared
    fixtures go in the area's ``conftest.py`` or a support module beside the tests."""
    tests = ROOT / "tests"
    loose = sorted(p.name for p in tests.glob("*.py") if p.name not in ("conftest.py", "__init__.py"))
    assert not loose, f"test modules directly under tests/ (move each into its area folder): {loose}"
    areas = sorted(p for p in tests.iterdir() if p.is_dir() and any(p.glob("test_*.py")))
    assert len(areas) >= 10, f"expected the tests grouped by area, found {[a.name for a in areas]}"
    undocumented = [a.name for a in areas if not (a / "__init__.py").is_file()
                    or not (a / "__init__.py").read_text(encoding="utf-8").startswith('"""')]
    assert not undocumented, f"area folders without an __init__.py docstring: {undocumented}"
    long = {p.relative_to(ROOT).as_posix(): n for a in areas for p in sorted(a.glob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert not long, f"test modules over {MAX_MODULE_LINES} lines (split them by theme): {long}"
