"""No production code reaches into another class's private fields or methods.

Parses every ``.py`` file of ``aerodaas/``, ``actors/``, ``schedulers/`` and ``clusters/`` with
:mod:`ast` and lists every attribute access ``expr._name`` (single leading underscore, not a dunder)
whose ``expr`` is not ``self``/``cls``, not ``super()``, not another project's module (``os._exit``),
not a private submodule of ours (``missionfile._common``), and not in the explicit allowlist below. A
class or function imported from a module is no module (``C._x`` is a reach-in), and neither is a private
global of one of our modules read from another (``driver._RAISE_OK``). Each allowlist entry names the
file, the accessed expression and why it is not a reach into another class's internals.
"""
from __future__ import annotations

import ast
import functools
import importlib.util
import re
from pathlib import Path

from tests.architecture import sources

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("aerodaas", "actors", "schedulers", "clusters")

#: (path relative to the repository root, expression as ``ast.unparse`` prints it) -> reason.
ALLOWED: dict[tuple[str, str], str] = {
    ("actors/data/channel_slots.py", "shm._name"): "stdlib SharedMemory: the resource tracker registers the leading-slash "
                                        "``_name``; the public ``name`` strips the slash, so it cannot unregister "
                                        "(the documented pre-3.13 workaround; 3.13 has ``track=False``)",
}


def _is_super_call(node: ast.expr) -> bool:
    """``super()._x``: the object's own (inherited) member, not another class's."""
    return isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "super"


def _is_private(attr: str) -> bool:
    return attr.startswith("_") and not (attr.startswith("__") and attr.endswith("__"))


#: our import names -> their folder (``aerodaas.actors`` is installed from ``actors/``, see pyproject.toml)
_OURS = {"aerodaas.actors": "actors", "aerodaas.schedulers": "schedulers", "aerodaas.clusters": "clusters",
         "aerodaas": "aerodaas"}


@functools.lru_cache(maxsize=None)
def _is_module(dotted: str) -> bool:
    """Whether ``dotted`` names a module or package: ours by its file under the repository, others by
    :func:`importlib.util.find_spec` (False when it cannot be found, e.g. a class imported from a module)."""
    for prefix, folder in sorted(_OURS.items(), key=lambda kv: -len(kv[0])):
        if dotted == prefix or dotted.startswith(prefix + "."):
            rest = dotted[len(prefix):].lstrip(".").replace(".", "/")
            base = ROOT / folder / rest if rest else ROOT / folder
            return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()
    try:
        return importlib.util.find_spec(dotted) is not None
    except (ImportError, ValueError):
        return False


def _ours(dotted: str) -> bool:
    return dotted == "aerodaas" or dotted.startswith("aerodaas.")


def _scan(tree: ast.Module, rel: str) -> list[tuple[int, str]]:
    """``(line, expression)`` of every private reach-in of the parsed file ``rel``, sorted by line. One walk
    collects the file's imports: a name bound by ``import X`` (or ``from P import M`` where ``P.M`` is a module)
    is a module; a private name of one of *our* modules read from another module is a reach-in too (unless it is a
    private submodule, e.g. ``missionfile._common``); a class or function imported by ``from P import N`` is not a
    module, so ``N._x`` is a reach-in."""
    modules: dict[str, str] = {}  # bound name -> dotted module path
    candidates: list[ast.Attribute] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            if _is_private(node.attr):
                candidates.append(node)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    modules[alias.asname] = alias.name
                else:
                    modules[alias.name.split(".")[0]] = alias.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom):
            for alias in node.names:
                if node.level:  # relative (none in the production code today): count it as a module
                    modules[alias.asname or alias.name] = ""
                elif _is_module(f"{node.module}.{alias.name}"):
                    modules[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    found = []
    for node in candidates:
        value = node.value
        if isinstance(value, ast.Name) and value.id in ("self", "cls"):
            continue
        if isinstance(value, ast.Name) and value.id in modules:
            mod = modules[value.id]
            if not _ours(mod) or _is_module(f"{mod}.{node.attr}"):
                continue  # another project's module (os._exit, sys._getframe), or a private submodule of ours
        if _is_super_call(value):
            continue
        expr = ast.unparse(node)
        if (rel, expr) not in ALLOWED:
            found.append((node.lineno, expr))
    return sorted(found)


#: any ``._`` (spaces or a line continuation allowed around the dot), and the ones on a bare ``self``/``cls``
_ANY_PRIVATE = re.compile(r"\.[\s\\]*_")
_OWN_PRIVATE = re.compile(r"(?<![\w.])(?:self|cls)[\s\\]*\.[\s\\]*_")


@functools.lru_cache(maxsize=1)
def _parsed() -> tuple[tuple[str, ast.Module], ...]:
    """The production files that may hold a reach-in, parsed once per session: ``(path from the root, tree)``.
    A file whose every ``._`` is on a bare ``self``/``cls`` (text check, erring towards parsing) cannot hold one
    and is skipped: it keeps the test well under 2 s on a loaded machine."""
    out = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            text = sources.source(path)
            if len(_ANY_PRIVATE.findall(text)) > len(_OWN_PRIVATE.findall(text)):
                out.append((path.relative_to(ROOT).as_posix(), sources.tree(path)))
    return tuple(out)


def _all_reach_ins() -> list[str]:
    return [f"{rel}:{line}: {expr}" for rel, tree in _parsed() for line, expr in _scan(tree, rel)]


def test_no_code_reaches_into_another_class_private_fields():
    found = _all_reach_ins()
    assert not found, (
        f"{len(found)} private reach-in(s) (use a public method/property of the owning class, "
        "or add an allowlist entry with a reason if the access is same-class):\n" + "\n".join(found))


def test_allowlist_entries_still_exist():
    """A stale allowlist entry would silently permit a future reach-in at that spot: keep it exact."""
    seen = {(rel, ast.unparse(n)) for rel, tree in _parsed() for n in ast.walk(tree)
            if isinstance(n, ast.Attribute) and _is_private(n.attr)}
    stale = sorted(set(ALLOWED) - seen)
    assert not stale, f"allowlist entries no longer in the code: {stale}"


def test_scanner_flags_a_reach_in_and_ignores_self_cls_modules_super_and_dunders():
    """The scanner itself, on small sources: ``other._secret``, ``self.peer._x``, a class's private member, and our
    module's private global are reach-ins; ``self``/``cls``, other projects' modules, ``super()`` and dunders are not."""
    src = ("import os\nfrom os import path\nclass A(B):\n    def f(self, other):\n"
           "        self._a = cls._b = os._exit\n        path._get_sep\n        other.__dict__\n"
           "        super()._kick()\n        self.peer._x = 1\n        return other._secret\n")
    assert _scan(ast.parse(src), "x.py") == [(9, "self.peer._x"), (10, "other._secret")]
    # a class imported from a module is no module; a private global of one of our modules is a reach-in, its
    # private submodule is not
    ours = ("from collections import OrderedDict\nfrom aerodaas.runtime import driver\n"
            "from aerodaas import missionfile\nOrderedDict._x\ndriver._RAISE_OK\nmissionfile._common\n")
    assert _scan(ast.parse(ours), "x.py") == [(4, "OrderedDict._x"), (5, "driver._RAISE_OK")]
    # the text pre-check parses every file that could hold one, and only skips files of bare self._x / cls._x
    for text in (src, "x = other._a", "y = self.peer._b", "z = (obj)._c", "w = obj.\\\n    _d", "v = myself._e"):
        assert len(_ANY_PRIVATE.findall(text)) > len(_OWN_PRIVATE.findall(text)), text
    own_only = "self._a = cls._b\nself . _c"
    assert len(_ANY_PRIVATE.findall(own_only)) == len(_OWN_PRIVATE.findall(own_only)) == 3
