"""Layers without cycles: the import graph between the sub-packages of ``aerodaas`` has no cycle.

Every production module (``aerodaas/``, ``actors/``, ``schedulers/``, ``clusters/``) is parsed with :mod:`ast`;
every import counts — at module level, inside functions and under ``TYPE_CHECKING`` — and so does
``importlib.import_module("literal")``. Each import is mapped to the sub-package it reaches (``aerodaas.<x>``: the
first package level below ``aerodaas``; ``aerodaas.schedulers.dispatch`` is part of ``schedulers``), and the graph
between sub-packages must be acyclic. ``aerodaas/__init__.py`` and ``aerodaas/cli.py`` are the top layer: they may
import anything and no sub-package imports them. The layer order is in ``docs/architecture.md`` (Layout).
"""
from __future__ import annotations

import ast
import functools
import re
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

from tests.architecture import sources

ROOT = Path(__file__).resolve().parents[2]
#: where each installed package's files are: ``aerodaas.actors`` is the repository's ``actors/`` and so on
PACKAGE_DIRS = {"aerodaas": ROOT / "aerodaas", "aerodaas.actors": ROOT / "actors",
                "aerodaas.schedulers": ROOT / "schedulers", "aerodaas.clusters": ROOT / "clusters"}
#: the top layer: the public API (``from aerodaas import *``) and the command line
TOP = "aerodaas (top)"
TOP_MODULES = {"aerodaas", "aerodaas.cli", "aerodaas.__main__"}
#: the sub-packages that belong to the top layer: the sub-commands (one module each, aerodaas/commands/)
TOP_PACKAGES = {"commands"}
#: entry points of their own above the top layer, imported by nothing in production: the bad-input and fault
#: catalogue (``python -m aerodaas.reliability``) drives the command line in-process as a user would
ENTRY_POINTS = {"reliability"}


def production_modules() -> dict[str, Path]:
    """Dotted module name → file, for every production module (a folder without ``__init__.py``, such as
    ``clusters/smoke/``, holds applications, not modules)."""
    out: dict[str, Path] = {}
    for pkg, base in PACKAGE_DIRS.items():
        for f in sorted(base.rglob("*.py")):
            rel = f.relative_to(base).with_suffix("").parts
            if pkg == "aerodaas" and rel and rel[0] in ("actors", "schedulers", "clusters"):
                continue
            if not all((base.joinpath(*rel[:i]) / "__init__.py").is_file() for i in range(len(rel))):
                continue
            if rel[-1] == "__init__":
                rel = rel[:-1]
            out[".".join((pkg, *rel))] = f
    return out


MODULES = production_modules()
#: the sub-packages: the package folders in ``aerodaas/`` and the three installed from the repository's top level
SUBPACKAGES = sorted(({d.name for d in (ROOT / "aerodaas").iterdir() if (d / "__init__.py").is_file()}
                      | {"actors", "schedulers", "clusters"}) - TOP_PACKAGES)


def layer_of(module: str) -> str | None:
    """The sub-package (``"app"``, ``"runtime"``, ``"actors"`` ...) a dotted module name belongs to, ``TOP`` for
    the top layer, None outside ``aerodaas``."""
    parts = module.split(".")
    if parts[0] != "aerodaas":
        return None
    if len(parts) == 1 or module in TOP_MODULES or parts[1] in TOP_PACKAGES:
        return TOP
    if parts[1] in SUBPACKAGES:
        return parts[1]
    return TOP


def _is_package(module: str) -> bool:
    return MODULES.get(module, Path()).name == "__init__.py"


def node_targets(node: ast.AST, pkg: str, known) -> list[str]:
    """The dotted targets one AST node imports: ``import X`` gives ``X``; ``from X import name`` gives ``X.name``
    when that is in ``known`` (the modules of ours), else ``X``, a relative ``X`` resolved against the package
    ``pkg``; a literal ``importlib.import_module("X")`` / ``__import__("X")`` gives ``X``; any other node, none."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom):
        if node.level:
            base = pkg.split(".")
            base = base[:len(base) - (node.level - 1)]
            target = ".".join(base + ([node.module] if node.module else []))
        else:
            target = node.module or ""
        return [f"{target}.{a.name}" if f"{target}.{a.name}" in known else target for a in node.names]
    if isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
            and isinstance(node.args[0].value, str):
        f = node.func
        name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
        if name in ("import_module", "__import__"):
            return [node.args[0].value]
    return []


def imports_of(module: str, path: Path) -> list[tuple[str, int]]:
    """(dotted target, line) for every import in the file: module level, in functions, in ``if TYPE_CHECKING``,
    and ``importlib.import_module("literal")`` / ``__import__("literal")``. ``from X import name`` counts as
    ``X.name`` when that is a module of ours, else as ``X``."""
    pkg = module if _is_package(module) else module.rpartition(".")[0]
    out: list[tuple[str, int]] = []
    for node in ast.walk(sources.tree(path)):
        out += [(target, node.lineno) for target in node_targets(node, pkg, MODULES)]
    return out


@functools.lru_cache(maxsize=1)
def package_graph() -> dict[tuple[str, str], list[str]]:
    """(importing sub-package, imported sub-package) → the module-level edges that make it
    (``"aerodaas.model.types:12 -> aerodaas.model.geo"``); made once per process, read by several tests."""
    edges: dict[tuple[str, str], list[str]] = defaultdict(list)
    for mod, path in MODULES.items():
        src = layer_of(mod)
        for target, line in imports_of(mod, path):
            dst = layer_of(target)
            if dst is None or dst == src:
                continue
            e = f"{mod}:{line} -> {target}"
            if e not in edges[(src, dst)]:
                edges[(src, dst)].append(e)
    return dict(edges)


def strongly_connected(nodes: list[str], succ: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components (Tarjan 1972, SIAM J. Comput. 1(2)), iterative."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    comps: list[list[str]] = []
    counter = 0
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(sorted(succ.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(succ.get(w, ())))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                comps.append(sorted(comp))
    return comps


def one_cycle(comp: list[str], succ: dict[str, set[str]]) -> list[str]:
    """A shortest cycle through the first package of a strongly connected component (breadth-first)."""
    start = comp[0]
    members = set(comp)
    prev: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(succ.get(v, ())):
                if w not in members:
                    continue
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(prev[path[-1]])
                    return [start] + path[::-1][1:] + [start]
                if w not in prev:
                    prev[w] = v
                    nxt.append(w)
        frontier = nxt
    return comp


def cycles_report(edges: dict[tuple[str, str], list[str]]) -> list[str]:
    """One text block per strongly connected component of more than one package: a cycle and its module edges."""
    succ: dict[str, set[str]] = defaultdict(set)
    for a, b in edges:
        if b != TOP:  # an import of the top layer is its own failure (test_nothing_imports_the_top_layer)
            succ[a].add(b)
    nodes = sorted({x for e in succ for x in (e, *succ[e])})
    out = []
    for comp in strongly_connected(nodes, succ):
        if len(comp) < 2:
            continue
        cyc = one_cycle(comp, succ)
        lines = [f"component {{{', '.join(comp)}}}; one cycle: {' -> '.join(cyc)}"]
        for a, b in zip(cyc, cyc[1:]):
            lines += [f"  {a} -> {b}:"] + [f"    {e}" for e in edges[(a, b)]]
        out.append("\n".join(lines))
    return out


def test_reader_sees_top_level_function_and_literal_imports(tmp_path):
    """The reader itself: all three kinds of import are found (so the cycle test below can fail)."""
    f = tmp_path / "m.py"
    f.write_text("import aerodaas.model.types\nfrom ..navigation import geo\n"
                 "def f():\n    from aerodaas.protocol import messages\n"
                 "    importlib.import_module('aerodaas.actors.drone.component')\n")
    got = {t for t, _ in imports_of("aerodaas.sim.world", f)}
    assert {"aerodaas.model.types", "aerodaas.protocol.messages", "aerodaas.actors.drone.component"} <= got
    assert "aerodaas.model.geo" in got or "aerodaas.navigation" in got
    comps = cycles_report({("a", "b"): ["x:1 -> y"], ("b", "c"): ["y:2 -> z"], ("c", "a"): ["z:3 -> x"],
                           ("c", "d"): ["z:4 -> w"]})
    assert len(comps) == 1 and "a -> b -> c -> a" in comps[0] and "w" not in comps[0].split(";")[0]


def test_no_import_cycle_between_subpackages():
    """No two sub-packages import each other, directly or through others (imports in functions count)."""
    cycles = cycles_report(package_graph())
    assert not cycles, f"{len(cycles)} import cycle(s) between sub-packages:\n" + "\n".join(cycles)


def test_nothing_imports_the_top_layer():
    """``aerodaas/__init__.py`` (the public API) and ``aerodaas/cli.py`` are imported only by entry points, and the
    entry points by nothing."""
    g = package_graph()
    bad = [e for (a, b), es in g.items() if b == TOP and a not in (TOP, *ENTRY_POINTS) for e in es]
    bad += [e for (a, b), es in g.items() if b in ENTRY_POINTS for e in es]
    assert not bad, "imports of the top layer or of an entry point:\n" + "\n".join(bad)


def test_the_actors_do_not_import_the_runtime():
    """The actors and the runtime share :mod:`aerodaas.protocol` (messages, specs, component ids), below both: the
    runtime starts the actors, the actors never import it."""
    g = package_graph()
    assert not g.get(("actors", "runtime")), "\n".join(g[("actors", "runtime")])
    assert g.get(("actors", "protocol")) and g.get(("runtime", "protocol"))  # the reader sees both sides


def test_the_runtime_does_not_import_the_actors():
    """The runtime starts the actors from the classes its entry point hands it
    (:class:`aerodaas.protocol.actor_classes.ActorClasses` on ``RunOptions.actors``) and binds the driver's handles
    from them: no module of the runtime imports a module of ``aerodaas.actors`` (in functions and under
    ``TYPE_CHECKING`` included), so the runtime does not depend on any concrete actor."""
    g = package_graph()
    bad = g.get(("runtime", "actors"), [])
    assert not bad, "the runtime imports actor modules:\n" + "\n".join(bad)
    assert g.get(("actors", "protocol")) and ("aerodaas.runtime.supervise" in MODULES)  # the reader sees the packages


#: imports every module named on the command line first, as in a fresh interpreter, in a tree of forked processes:
#: the root has imported the third-party libraries (not ``aerodaas``: its modules are removed from ``sys.modules``),
#: and each package's process has imported that package alone, the way any first import of a module below it
#: starts (``import a.b.c`` runs ``a``, then ``a.b``, then ``a.b.c``: the state when ``a.b.c``'s own code starts is
#: the same whichever of ``a.b``'s modules is imported, so it is made once per package, not once per module). Each
#: module is then imported in a forked child of its package's process (a sub-package: the child imports it, checks
#: its own modules and ends), so every module's code still executes afresh with nothing of ours loaded but its
#: packages, as in a new process; a package that fails fails every module below it, as it would in a new process;
#: a module that its package's own import loaded (about a fifth of them) was imported first by that import, and
#: needs no child.
#: The root keeps each source file's compiled code (``SourceLoader.source_to_code``, keyed by path and source
#: bytes), which the children inherit: without bytecode files (``PYTHONDONTWRITEBYTECODE=1``, a fresh checkout)
#: each child otherwise compiled every module it imports again. Prints ``module: error`` for each failure
_FRESH_IMPORTS = """
import importlib, importlib.machinery, os, sys, traceback
compiled = {}
source_to_code = importlib.machinery.SourceFileLoader.source_to_code
def cached_source_to_code(self, data, path, *args, **kwargs):
    key = (path, bytes(data))
    if key not in compiled:
        compiled[key] = source_to_code(self, data, path, *args, **kwargs)
    return compiled[key]
importlib.machinery.SourceFileLoader.source_to_code = cached_source_to_code
mods = sys.argv[1:]
for m in mods:
    try:
        importlib.import_module(m)
    except BaseException:
        pass
for k in [k for k in sys.modules if k == "aerodaas" or k.startswith("aerodaas.")]:
    del sys.modules[k]
below = {}  # package -> the listed modules one level below it (a package's own name: the key "")
for m in mods:
    below.setdefault(m.rpartition(".")[0], []).append(m)
def below_first(m):
    # in a process where m is imported (as the first import of anything below it would have imported it): each
    # listed module below m, first; True when all of them import
    return all([first(d) for d in below.get(m, [])])
def first(m):
    # m first, in the state of its package's process: a module that its package's import loaded is imported first
    # by importing the package, which already succeeded here, so it needs no child of its own (its own modules are
    # checked from here: they start from this state too); any other in a forked child, which then checks the
    # modules below it. True when m and everything below it import
    if m in sys.modules:
        return below_first(m)
    sys.stdout.flush()
    pid = os.fork()
    if pid:
        return os.waitpid(pid, 0)[1] == 0
    try:
        importlib.import_module(m)
    except BaseException:
        print(m + ": " + traceback.format_exc().strip().splitlines()[-1], flush=True)
        for d in sorted(x for x in mods if x.startswith(m + ".")):
            print(d + ": its package " + m + " does not import first", flush=True)
        os._exit(1)
    ok = below_first(m)
    sys.stdout.flush()
    os._exit(0 if ok else 1)
unrooted = sorted(set(mods) - {m for k, v in below.items() for m in v if k == "" or k in mods})
ok = below_first("") and not unrooted
if unrooted:
    print("modules whose package is not listed (not checked): " + ", ".join(unrooted), flush=True)
sys.exit(0 if ok else 1)
"""


@pytest.mark.timeout(1800)  # ~380 modules, each in a forked child: minutes at load 10-16
def test_every_module_imports_first_in_a_fresh_process():
    """Each production module imports on its own, first (no import-order dependence, no circular import that the
    usual order hides: a dispatcher actor unpickling a DEMS policy died of one). ``__main__`` modules run when
    imported and are left out."""
    mods = sorted(m for m in MODULES if not m.endswith(".__main__"))
    r = subprocess.run([sys.executable, "-c", _FRESH_IMPORTS, *mods], capture_output=True, text=True, timeout=1800,
                       cwd=ROOT / "tests")
    assert r.returncode == 0, f"modules that do not import first:\n{r.stdout[-4000:]}{r.stderr[-2000:]}"


def documented_layers() -> dict[str, int]:
    """Sub-package → its line in the layer block of ``docs/architecture.md`` (bottom 0): the names on each numbered
    line, parenthesised remarks left out; the top layer (``aerodaas/__init__.py``, the CLI) is :data:`TOP`, and an
    entry point (``reliability``) one line above it."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    block = text.split("**Layers.**", 1)[1].split("```", 2)[1]
    block = re.sub(r"\([^)]*\)", " ", block, flags=re.S)
    levels: dict[str, int] = {}
    level = -1
    for line in block.splitlines():
        m = re.match(r"\s*(\d+)\s+(.*)", line)
        if m:
            level = int(m.group(1))
            if "aerodaas/__init__.py" in m.group(2):
                levels[TOP] = level
                continue
        words = re.findall(r"[a-z_]+", m.group(2) if m else line)
        for w in words:
            if w in SUBPACKAGES:
                levels[w] = level + (1 if w in ENTRY_POINTS else 0)
    return levels


def test_every_import_goes_down_the_documented_layers():
    """The layer order that docs/architecture.md shows is the one the code has: every sub-package is on a line,
    and every import between sub-packages goes to a lower line (the docs and the code cannot drift apart)."""
    levels = documented_layers()
    missing = sorted(set(SUBPACKAGES) - set(levels))
    assert not missing, f"sub-packages not in the layer block of docs/architecture.md: {missing}"
    upward = [f"{src} (line {levels[src]}) -> {dst} (line {levels[dst]}): {edges[0]}"
              for (src, dst), edges in sorted(package_graph().items()) if levels[dst] >= levels[src]]
    assert not upward, "imports that do not go down the documented layers:\n" + "\n".join(upward)


def test_the_layer_reader_reads_the_block():
    """The reader itself: known placements of the documented block."""
    levels = documented_layers()
    assert levels["model"] == 0 and levels["video"] == 0 and levels["clusters"] == 0
    assert levels["runtime"] == 8 and levels["actors"] == 7 and levels[TOP] == 11 and levels["reliability"] == 12
