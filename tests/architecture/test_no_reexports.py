"""One home per name: a module other than a package's ``__init__`` never re-exports what it imports. An import it
does not use itself, kept with ``# noqa: F401`` so that an old import path stays alive, lets two paths name one
thing and hides where it is defined; its importers import from the defining module instead. An AST scan of
``aerodaas/``, ``actors/``, ``schedulers/`` and ``clusters/``: every import statement that carries ``noqa: F401``
(or a bare ``noqa``) on any of its lines fails, but for the imports in :data:`ALLOWED`, which are kept for their
effect, not for a name: a check that an optional dependency is there, or modules loaded before a fork."""
from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

from tests.architecture import sources

ROOT = Path(__file__).resolve().parents[2]
SCANNED = ("aerodaas", "actors", "schedulers", "clusters")
NOQA = re.compile(r"#\s*noqa\b(?::\s*(?P<codes>[A-Z0-9, ]+))?", re.IGNORECASE)

#: (file relative to the repository, the imported names): imports kept for their effect, each with its reason
ALLOWED = {
    # is zstandard there? the recorder then writes zstd chunks, else uncompressed ones
    ("aerodaas/recording/writer.py", ("zstandard",)),
    # is PyTorch (the [train] extra) there? else `aerodaas train` stops with the install command
    ("aerodaas/commands/train.py", ("torch",)),
    # is dora-rs there? else the peers benchmark says why its column is missing
    ("aerodaas/bench/peers_dora.py", ("dora",)),
    # the fork server loads the built-in schedulers once before it forks policy processes, so each starts warm
    ("aerodaas/bench/isolation_preload.py", ("analytics_baselines", "analytics_dems", "analytics_evplan",
                                             "analytics_gainplan", "analytics_laplan", "single_machine_jit")),
}


def _silences_f401(lines: list[str], node: ast.stmt) -> bool:
    for line in lines[node.lineno - 1:node.end_lineno]:
        for m in NOQA.finditer(line):
            codes = m.group("codes")
            if codes is None or "F401" in codes.upper():
                return True
    return False


@functools.lru_cache(maxsize=None)
def reexports(root: Path = ROOT) -> tuple[tuple[str, int, tuple[str, ...]], ...]:
    """(file, line, imported names) of every import that silences F401 in a non-``__init__`` module."""
    found = []
    for top in SCANNED:
        for path in sorted((root / top).rglob("*.py")):
            if path.name == "__init__.py":
                continue
            lines = sources.source(path).splitlines()
            for node in ast.walk(sources.tree(path)):
                if isinstance(node, (ast.Import, ast.ImportFrom)) and _silences_f401(lines, node):
                    names = tuple(a.asname or a.name for a in node.names)
                    found.append((path.relative_to(root).as_posix(), node.lineno, names))
    return tuple(found)


def test_no_module_re_exports_an_import():
    bad = [f"{f}:{line}: {', '.join(names)}" for f, line, names in reexports() if (f, names) not in ALLOWED]
    assert not bad, ("imports kept only to be imported from here again (# noqa: F401): import each name from the "
                     "module that defines it, and delete the re-export:\n" + "\n".join(bad))


def test_the_allowed_imports_are_still_there():
    """A stale entry of :data:`ALLOWED` would let a new re-export of the same names through unnoticed."""
    present = {(f, names) for f, _, names in reexports()}
    assert ALLOWED <= present, sorted(ALLOWED - present)


def test_the_scan_finds_a_re_export(tmp_path):
    """The scan is not vacuous: a module that re-exports a name is found, an ``__init__`` and an import without
    the ``noqa`` are not."""
    pkg = tmp_path / "aerodaas" / "pkg"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("from os.path import join  # noqa: F401\n")
    (pkg / "shim.py").write_text("from os.path import (join,  # noqa: F401\n    split)\nimport os\n")
    (pkg / "bare.py").write_text("import json  # noqa\n")
    (pkg / "other.py").write_text("import sys  # noqa: E402\n")
    for top in SCANNED[1:]:
        (tmp_path / top).mkdir()
    assert reexports(tmp_path) == (("aerodaas/pkg/bare.py", 1, ("json",)),
                                   ("aerodaas/pkg/shim.py", 1, ("join", "split")))
