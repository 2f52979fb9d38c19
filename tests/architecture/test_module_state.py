"""No module-level mutable state in production code outside the one plug-in registry object and the
process object (its signal handling and its Ray connection), each documented where it is defined. An AST scan of
``aerodaas/``, ``actors/``, ``schedulers/`` and ``clusters/``: a module-level name bound to a mutable value — a
list, dict or set display or comprehension, a call of a mutable container type (``list()``, ``dict()``,
``defaultdict()``, ``deque()``...), or of a stateful object (``threading.local()``, ``itertools.count()``,
``ContextVar()``) — that some code of the scanned tree mutates (``NAME.append(...)``, ``NAME[k] = v``, ``del
NAME[k]``, ``global NAME``...) is state. A module-level table that nothing writes (``FAILSAFE_MODES = {...}``), a
tuple or frozenset, a constant, a typing alias or a logger is not. A memo of a pure function is written with
``functools.cache`` on that function (the standard library's memo, keyed by the arguments; a decorated ``def`` is
no binding the scan reads), never as a hand-kept dict; a lazily built object as a cached factory function, never a
name rebound with ``global``. State that belongs to an actor, a run, a recorder or a command is a field of the
object that owns it, passed to the code that needs it. No Ray, no firmware."""
from __future__ import annotations

import ast
from pathlib import Path

from tests.architecture import sources

ROOT = Path(__file__).resolve().parents[2]
SCANNED = ("aerodaas", "actors", "schedulers", "clusters")
#: calls that build a mutable container
CONTAINERS = {"list", "dict", "set", "defaultdict", "OrderedDict", "deque", "Counter", "WeakValueDictionary",
              "WeakKeyDictionary", "WeakSet", "bytearray"}
#: calls that build an object holding state of its own however it is used
STATEFUL = {"local", "count", "ContextVar"}
#: calls whose result is not state: a logger (configured by the application, not by us), a frozen value
NOT_STATE = {"getLogger", "frozenset", "tuple", "TypeVar", "NewType", "ParamSpec"}
#: applications among the scanned files (their top level is the application's own code, run as a script)
APPLICATIONS = {"clusters/smoke/cloud_detect.py"}
#: methods that change a container in place
MUTATORS = {"append", "extend", "insert", "pop", "popleft", "appendleft", "remove", "clear", "update", "add",
            "discard", "setdefault", "sort", "reverse", "popitem"}

#: (file relative to the repository, module-level name): the state that is allowed, each documented at its definition
ALLOWED = {
    # the one plug-in registry object (aerodaas.plugins.registry.PluginRegistry): every plug-in of the process
    ("aerodaas/plugins/registry.py", "REGISTRY"),
    # the process's signal handling, Ray connection and shared MAVLink links (aerodaas.process.state.ProcessState):
    # signal.signal, ray.init and a bound UDP port are process-wide by nature
    ("aerodaas/process/state.py", "PROCESS"),
}
#: state found when the scan was introduced, still to be moved into an owned object: listed so that
#: nothing new is added; an entry that no longer matches fails the test (remove it here). Empty since the MAVLink
#: links a process's robots share moved into :data:`aerodaas.process.state.PROCESS` (``mavlink_links``)
KNOWN_DEBT: set[tuple[str, str]] = set()


def _call_name(node: ast.AST) -> str:
    if not isinstance(node, ast.Call):
        return ""
    f = node.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def module_bindings(tree: ast.Module) -> dict[str, int]:
    """``{name: line}`` of the module-level names ``tree`` binds to a mutable container, a stateful object or any
    other object a call returns (an instance, whose attributes a function may set)."""
    out: dict[str, int] = {}
    for node in tree.body:
        if isinstance(node, ast.Assign):
            targets, value = node.targets, node.value
        elif isinstance(node, ast.AnnAssign) and node.value is not None:
            targets, value = [node.target], node.value
        else:
            continue
        mutable = isinstance(value, (ast.List, ast.Dict, ast.Set, ast.ListComp, ast.DictComp, ast.SetComp)) or (
            isinstance(value, ast.Call) and _call_name(value) not in NOT_STATE)
        for t in targets:
            if isinstance(t, ast.Name) and mutable:
                out[t.id] = node.lineno
    return out


def _in_functions(tree: ast.AST) -> list[ast.AST]:
    """Every node inside a function, method or lambda of ``tree``: code that runs after the module was imported
    (a module's top level building its own table, ``TABLE[k] = ...`` in a loop, is construction, not state)."""
    out: list[ast.AST] = []
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            out.extend(ast.walk(fn))
    return out


def mutated_names(tree: ast.AST) -> set[str]:
    """Names whose value a function of ``tree`` changes in place (a mutating method, an item or attribute
    assignment, ``del``) or rebinds with ``global``; for ``module.NAME.append(...)`` both ``module`` and
    ``NAME``."""
    out: set[str] = set()

    def chain(node: ast.AST) -> None:
        while isinstance(node, (ast.Subscript, ast.Attribute)):
            if isinstance(node, ast.Attribute):
                out.add(node.attr)
            node = node.value
        if isinstance(node, ast.Name):
            out.add(node.id)

    for n in _in_functions(tree):
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr in MUTATORS:
            chain(n.func.value)
        elif isinstance(n, (ast.Assign, ast.AugAssign, ast.Delete, ast.AnnAssign)):
            targets = n.targets if isinstance(n, (ast.Assign, ast.Delete)) else [n.target]
            for t in targets:
                if isinstance(t, (ast.Subscript, ast.Attribute)):
                    chain(t.value)
        elif isinstance(n, ast.Global):
            out.update(n.names)
    return out


def scan(files: dict[str, str]) -> set[tuple[str, str]]:
    """``(file, name)`` of every module-level mutable state among ``files`` (``{relative path: source}``), see
    :func:`scan_trees`."""
    return scan_trees({rel: ast.parse(src, rel) for rel, src in files.items()})


def scan_trees(trees: dict[str, ast.Module]) -> set[tuple[str, str]]:
    """``(file, name)`` of every module-level mutable state among ``trees`` (``{relative path: syntax tree}``): a
    mutable binding (:func:`module_bindings`) mutated anywhere in them, a stateful object however used, and a
    module-level name rebound with ``global``."""
    mutated: set[str] = set().union(*(mutated_names(t) for t in trees.values()))
    found: set[tuple[str, str]] = set()
    for rel, tree in trees.items():
        stateful = {t.id for node in tree.body if isinstance(node, (ast.Assign, ast.AnnAssign))
                    for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
                    if isinstance(t, ast.Name) and _call_name(node.value) in STATEFUL}
        for name in module_bindings(tree):
            if name in mutated or name in stateful:
                found.add((rel, name))
        for n in ast.walk(tree):
            if isinstance(n, ast.Global):
                found.update((rel, g) for g in n.names)
    return found


def _production_trees() -> dict[str, ast.Module]:
    """The scanned files' syntax trees (shared with the other architecture checks: :mod:`tests.architecture.sources`)
    by path from the repository's root, the applications left out."""
    return {str(p.relative_to(ROOT)): sources.tree(p)
            for d in SCANNED for p in sorted((ROOT / d).rglob("*.py"))
            if str(p.relative_to(ROOT)) not in APPLICATIONS}


def test_the_scan_finds_module_state_and_leaves_tables_and_constants_alone():
    src = ("import threading, itertools\nfrom collections import defaultdict\n"
           "LISTENERS = []\nFLAGS = [False]\n_CACHE = {}\nSEEN = defaultdict(list)\nTABLE = {'a': 1}\n"
           "NAMES = ('a', 'b')\nFROZEN = frozenset({1})\nLOCAL = threading.local()\nSEQ = itertools.count(1)\n"
           "import logging\nlog = logging.getLogger(__name__)\n_x = None\nclass Box:\n    pass\nBOX = Box()\nBUILT = {}\nfor k in NAMES:\n    BUILT[k] = 1\n\n"
           "def f(k):\n    global _x\n    _x = k\n    FLAGS[0] = True\n    _CACHE[k] = TABLE[k]\n"
           "    SEEN[k].append(NAMES)\n    BOX.n = BUILT[k]\n    log.disabled = True\n    return FROZEN\n")
    other = "from m import LISTENERS\nimport m\n\ndef g(fn):\n    m.LISTENERS.append(fn)\n"
    found = scan({"m.py": src, "n.py": other})
    assert found == {("m.py", n) for n in ("LISTENERS", "FLAGS", "_CACHE", "SEEN", "LOCAL", "SEQ", "_x",
                                                "BOX")}


def test_no_module_level_mutable_state_outside_the_registry_and_the_process_object():
    found = scan_trees(_production_trees())
    new = sorted(found - ALLOWED - KNOWN_DEBT)
    assert not new, ("module-level mutable state (move it into an owned object, see tests/architecture/test_module_state.py):\n"
                     + "\n".join(f"{f}: {n}" for f, n in new))
    gone = sorted((KNOWN_DEBT | ALLOWED) - found)
    assert not gone, f"listed here but no longer found (remove the entry): {gone}"


def test_the_former_module_level_state_is_gone():
    """``MISSION_LISTENERS``, ``STOP_SIGNALS``, ``_RAISE_OK``, ``IN_MISSION`` (driver) and ``_STATE``/``_EARLY``
    (ray_start) were module-level lists and dicts; each is now a field of an owned object."""
    bound = {(rel, name) for rel, tree in _production_trees().items() for name in module_bindings(tree)}
    named = {"MISSION_LISTENERS", "STOP_SIGNALS", "_RAISE_OK", "IN_MISSION", "_STATE", "_EARLY", "_ENTRIES",
             "_LOADED", "_BY_VALUE", "_LINKS", "_LINKS_LOCK"}
    assert {n for _, n in bound} & named == set()
