"""The file-level import graph: what ``tests/architecture/test_layers.py`` checks between
sub-packages, checked between files.

The graph has one node per production file of ours (``aerodaas/``; ``actors/``, ``schedulers/``, ``clusters/``
as the installed ``aerodaas.actors`` ...; the example applications of ``apps/`` as ``apps.<stem>``) and one edge per
import of another of them, read from the AST: at module top, under ``if TYPE_CHECKING``, inside functions, and
``importlib.import_module("literal")``. ``from X import name`` is an edge to ``X.name`` when that is a module of
ours, else to ``X`` (a package's ``__init__``). Importing ``a.b.c`` also runs the packages ``a.b`` and ``a``: an
edge to each of them too, except (implicitly) to the importing file's own parent packages, which Python runs before
the file, and to ``aerodaas`` (the lazy public API, below).

Two rules:

- **No cycle among files**: every strongly connected component (Tarjan 1972) has one file. An import inside a
  function counts, so a cycle hidden by moving one import into a function is still found.
- **Imports at module top**: an import inside a function (or a literal ``import_module`` call there) carries a
  marker comment on one of its lines, ``# lazy: <reason>``, the reason being an optional or heavy third-party
  dependency (onnxruntime, cv2, torch, av, fastapi, matplotlib, ray/numpy where ``aerodaas --help`` must start
  without it ...) or a documented start-up cost. A cycle is not a reason: it is broken instead (a shared type
  moved down, a module split, an object passed).

The public API's PEP 562 ``__getattr__`` in ``aerodaas/__init__.py`` (start-up) resolves names with
``import_module(origin)``, not a literal, so it is neither an edge nor an import to mark.

``KNOWN_CYCLE_FILES`` and ``KNOWN_UNMARKED`` name today's offenders so that the suite passes while they are fixed;
a file that no longer offends must be taken off (``test_the_known_lists_are_current``), so the lists only shrink.
"""
from __future__ import annotations

import ast
import functools
import re
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

from tests.architecture import sources
from tests.architecture.test_layers import MODULES, ROOT, node_targets, one_cycle, strongly_connected

#: the example applications: loaded by ``aerodaas run`` as modules of their own, imported by nothing of ours
APPS = {f"apps.{f.stem}": f for f in sorted((ROOT / "apps").glob("*.py"))}
#: every file of the graph: dotted name -> path
FILES: dict[str, Path] = {**MODULES, **APPS}
#: ``# lazy: <reason>`` on a line of the import; the reason is group 1
MARKER = re.compile(r"#\s*lazy:\s*(\S.*)$")
#: words that make a reason not a reason: a cycle is broken, not hidden
NOT_A_REASON = re.compile(r"\b(cycle|cyclic|circular)\b", re.I)


@dataclass(frozen=True)
class Import:
    """One import statement's target as the graph sees it.

    ``target``: the dotted module imported (ours or not); ``line``/``end``: the statement's first and last line
    (1-based); ``in_function``: inside a ``def``/``lambda`` (at any depth) rather than run at import;
    ``reason``: the text after ``# lazy:`` on one of its lines, None without a marker."""

    target: str
    line: int
    end: int
    in_function: bool
    reason: str | None


def _resolve(target: str) -> str:
    """``target`` or, for ``aerodaas.x.y.Name``, the longest prefix that is a file of ours."""
    t = target
    while t and t not in FILES and "." in t:
        t = t.rpartition(".")[0]
    return t if t in FILES else target


def imports_in(module: str, path: Path) -> list[Import]:
    """Every import of the file ``path`` (dotted name ``module``): statements at any depth and literal
    ``import_module``/``__import__`` calls. A relative import is resolved against ``module``'s package. Raises
    SyntaxError for a file Python cannot parse."""
    lines = sources.source(path).splitlines()
    is_pkg = path.name == "__init__.py"
    pkg = module if is_pkg else module.rpartition(".")[0]
    out: list[Import] = []

    def reason(node: ast.AST) -> str | None:
        for ln in lines[node.lineno - 1:(node.end_lineno or node.lineno)]:
            m = MARKER.search(ln)
            if m:
                return m.group(1).strip()
        return None

    def add(target: str, node: ast.AST, in_fn: bool) -> None:
        out.append(Import(_resolve(target), node.lineno, node.end_lineno or node.lineno, in_fn, reason(node)))

    def visit(node: ast.AST, in_fn: bool) -> None:
        for target in node_targets(node, pkg, FILES):
            add(target, node, in_fn)
        deeper = in_fn or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        for child in ast.iter_child_nodes(node):
            visit(child, deeper)

    visit(sources.tree(path), False)
    return out


def _targets(mod: str, target: str) -> list[str]:
    """The files of ours an import of ``target`` in ``mod`` runs: ``target`` itself, and its parent packages
    less ``mod``'s own (already run) and ``aerodaas``."""
    parts = target.split(".")
    own = {".".join(mod.split(".")[:k]) for k in range(1, mod.count(".") + 1)}
    parents = [".".join(parts[:k]) for k in range(2, len(parts))]
    ts = [t for t in parents if t not in own] + [target]
    return [t for t in ts if t in FILES and t != mod]


@functools.lru_cache(maxsize=1)
def file_graph() -> dict[str, dict[str, list[str]]]:
    """importing file -> imported file -> the imports that make the edge (``"line 12 (in a function)"``); made once
    per process, read by several tests."""
    g: dict[str, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    for mod, path in FILES.items():
        for imp in imports_in(mod, path):
            where = f"line {imp.line}" + (" (in a function)" if imp.in_function else "")
            for t in _targets(mod, imp.target):
                if where not in g[mod][t]:
                    g[mod][t].append(where)
    return {m: dict(ts) for m, ts in g.items()}


def cycles(g: dict[str, dict[str, list[str]]]) -> list[tuple[list[str], str]]:
    """(the files of a strongly connected component of more than one file, a report: one shortest cycle through
    its first file with the lines of each edge) for every such component."""
    succ = {a: set(bs) for a, bs in g.items()}
    nodes = sorted({x for a, bs in succ.items() for x in (a, *bs)})
    out = []
    for comp in strongly_connected(nodes, succ):
        if len(comp) < 2:
            continue
        cyc = one_cycle(comp, succ)
        text = [f"{len(comp)} files: {', '.join(comp)}", f"  one cycle: {' -> '.join(cyc)}"]
        text += [f"    {a} -> {b}: {', '.join(g[a][b])}" for a, b in zip(cyc, cyc[1:])]
        out.append((comp, "\n".join(text)))
    return out


def unmarked(mod: str, path: Path) -> list[str]:
    """The imports inside functions of one file without a valid ``# lazy: <reason>`` marker, as
    ``"path:line: target"`` (``"(reason: ...)"`` appended when the marker's reason is a cycle)."""
    rel = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
    bad: list[str] = []
    for imp in imports_in(mod, path):
        if not imp.in_function:
            continue
        if imp.reason is None:
            bad.append(f"{rel}:{imp.line}: {imp.target}")
        elif NOT_A_REASON.search(imp.reason):
            bad.append(f"{rel}:{imp.line}: {imp.target} (reason: {imp.reason!r} - break the cycle instead)")
    return list(dict.fromkeys(bad))


#: files in an import cycle today (to be emptied)
KNOWN_CYCLE_FILES: set[str] = set()

#: files with unmarked imports inside functions today (to be emptied)
KNOWN_UNMARKED: set[str] = set()


def test_the_reader_sees_every_kind_of_import(tmp_path):
    """The reader itself, so the rules below can fail: top-level, TYPE_CHECKING, function-level and literal
    ``import_module`` imports, relative ones resolved, markers read from any line of a statement, and a
    three-file cycle found with a file outside it left out."""
    f = tmp_path / "m.py"
    f.write_text("from typing import TYPE_CHECKING\nimport aerodaas.model.types\n"
                 "if TYPE_CHECKING:\n    from ..navigation import geo\n"
                 "def f():\n    from aerodaas.protocol import (messages,\n        specs)  # lazy: heavy\n"
                 "    import json\n"
                 "    importlib.import_module('aerodaas.actors.drone.component')  # lazy: a cycle\n"
                 "    g = lambda: __import__('cv2')\n", encoding="utf-8")
    got = {(i.target, i.in_function, i.reason) for i in imports_in("aerodaas.sim.world", f)}
    assert ("aerodaas.model.types", False, None) in got
    assert ("aerodaas.navigation.geo", False, None) in got or ("aerodaas.navigation", False, None) in got
    assert ("aerodaas.protocol.messages", True, "heavy") in got and ("json", True, None) in got
    assert ("aerodaas.actors.drone.component", True, "a cycle") in got and ("cv2", True, None) in got
    bad = unmarked("aerodaas.sim.world", f)
    assert [b.split(": ", 1)[1] for b in bad] == [
        "json", "aerodaas.actors.drone.component (reason: 'a cycle' - break the cycle instead)", "cv2"]
    assert _targets("aerodaas.sim.world", "aerodaas.protocol.messages") == ["aerodaas.protocol",
                                                                              "aerodaas.protocol.messages"]
    sub = "aerodaas.emulators.mavlink"
    assert _targets(f"{sub}.vehicle", f"{sub}.link") == [f"{sub}.link"] and _targets(f"{sub}.vehicle", sub) == [sub]
    g = {"a": {"b": ["line 1"]}, "b": {"c": ["line 2 (in a function)"]}, "c": {"a": ["line 3"], "d": ["line 4"]}}
    found = cycles(g)
    assert len(found) == 1 and found[0][0] == ["a", "b", "c"] and "a -> b -> c -> a" in found[0][1]


def test_no_import_cycle_among_files():
    """No file imports itself through others (imports in functions and under TYPE_CHECKING count)."""
    found = cycles(file_graph())
    new = [text for comp, text in found if not set(comp) <= KNOWN_CYCLE_FILES]
    assert not new, f"{len(new)} import cycle(s) among files (of {len(found)}):\n" + "\n".join(new)


def test_imports_in_functions_are_marked_lazy():
    """Every import inside a function says why it is not at module top (``# lazy: <reason>``)."""
    bad = [b for mod, path in FILES.items() if mod not in KNOWN_UNMARKED for b in unmarked(mod, path)]
    assert not bad, f"{len(bad)} import(s) inside functions without '# lazy: <reason>':\n" + "\n".join(bad)


def test_the_known_lists_are_current():
    """A file fixed is taken off its KNOWN list (the lists only shrink) and every name on them is a file."""
    in_cycles = {m for comp, _ in cycles(file_graph()) for m in comp}
    stale = sorted(KNOWN_CYCLE_FILES - in_cycles) + sorted(m for m in KNOWN_UNMARKED
                                                           if m not in FILES or not unmarked(m, FILES[m]))
    assert not stale, "no longer offending (take them off the KNOWN lists): " + ", ".join(stale)
