"""The framework has no branch on a built-in sensor or backend name: built-ins go through the same
contract as plug-ins (their classes declare what the framework needs), so production code never compares a
sensor's ``type`` or a robot's ``backend`` with ``"camera"``, ``"mavlink"``... nor keeps a table keyed by them.

The scan reads the code's syntax tree (:mod:`ast`): comparisons (``==``, ``!=``, ``in``, ``not in``) of a
built-in name with an expression ending in ``type``/``backend``/``kind``/``name`` (an attribute, a variable, a
``["type"]`` subscript, ``.get("type")`` or ``getattr(x, "type")``), ``match``/``case`` on a built-in name, and
literals (dict keys, tuples, lists, sets) of two or more built-in names of one kind and nothing else (a table of
the built-ins; a vocabulary of topic segments or plan component kinds that holds other words too is not one)."""
from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SENSORS = frozenset({"camera", "odometry", "stat_stream", "stat-stream"})
BACKENDS = frozenset({"sim", "mavlink", "tello", "replay"})
#: the expression a name is compared with -> the names that would be a branch on a built-in there ("kind" is a
#: backend's name; a plan component's kind, such as "camera", is not a sensor type)
SUBJECTS = {"type": SENSORS, "sensor_type": SENSORS, "backend": BACKENDS, "backend_name": BACKENDS,
            "kind": BACKENDS, "name": BACKENDS | SENSORS}
#: production code: the framework, its actors and schedulers (the emulators are simulated vehicles, not framework)
ROOTS = ("aerodaas", "actors", "schedulers", "clusters")
EXCLUDED = ("aerodaas/emulators/",)


def _tail(node: ast.AST) -> str | None:
    if isinstance(node, ast.Attribute):
        return node.attr
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant):
        return str(node.slice.value)
    if isinstance(node, ast.Call) and node.args and isinstance(node.args[-1 if _is_getattr(node) else 0], ast.Constant):
        if _is_getattr(node) and len(node.args) >= 2:
            return str(node.args[1].value) if isinstance(node.args[1], ast.Constant) else None
        if isinstance(node.func, ast.Attribute) and node.func.attr == "get":
            return str(node.args[0].value)
    return None


def _is_getattr(node: ast.Call) -> bool:
    return isinstance(node.func, ast.Name) and node.func.id == "getattr"


def _strings(node: ast.AST) -> set[str]:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return {node.value}
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return {e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)}
    return set()


def branches_on_builtin_names(source: str, where: str) -> list[str]:
    """Every place in ``source`` (Python) that branches on, or tabulates, a built-in sensor or backend name, as
    ``where:line: code``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            if any(_tail(a) in SUBJECTS and _strings(b) & SUBJECTS[_tail(a)]
                   for a in sides for b in sides if a is not b):
                found.append(f"{where}:{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, (ast.Dict, ast.Tuple, ast.List, ast.Set)):
            keys = node.keys if isinstance(node, ast.Dict) else node.elts
            names = {k.value for k in keys if isinstance(k, ast.Constant) and isinstance(k.value, str)}
            if len(names) >= 2 and (names <= BACKENDS or names <= SENSORS):
                found.append(f"{where}:{node.lineno}: a table of built-in names {sorted(names & (BACKENDS | SENSORS))}")
        elif isinstance(node, ast.match_case) and isinstance(node.pattern, ast.MatchValue):
            if _strings(node.pattern.value) & (BACKENDS | SENSORS):
                found.append(f"{where}:{node.pattern.lineno}: case {ast.unparse(node.pattern)}")
    return found


def test_the_scan_finds_each_form_of_branch():
    code = '''
if s.type == "camera": pass
if robot.cfg.backend != "mavlink": pass
if getattr(src, "type", None) != "odometry": pass
if d["type"] in ("stat_stream", "x"): pass
if cfg.get("backend") == "replay": pass
NAVIGABLE = {"sim": True, "tello": True}
match backend:
    case "tello": pass
if source == "sim" and c.kind in ("camera", "analytics"): pass
RESERVED = frozenset({"camera", "events", "odometry"})
KNOWN = ("camera", "odometry")
'''
    found = branches_on_builtin_names(code, "x.py")
    assert [f.split(":")[1] for f in found] == ["2", "3", "4", "5", "6", "7", "9", "12"], found


def test_production_code_has_no_branch_on_a_builtin_sensor_or_backend_name():
    found = []
    for root in ROOTS:
        for path in sorted((REPO / root).rglob("*.py")):
            rel = path.relative_to(REPO).as_posix()
            if not rel.startswith(EXCLUDED):
                found += branches_on_builtin_names(path.read_text(encoding="utf-8"), rel)
    assert not found, "branches on built-in sensor/backend names (declare it on the class instead):\n" + "\n".join(found)
