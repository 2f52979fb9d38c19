"""One home per name on the vehicle backends: a backend class neither forwards to its own concern objects nor grows a
property per state field again.

An AST scan of every class in ``aerodaas/backends/`` and ``examples/plugins/`` that derives (directly or through
another scanned class) from ``VehicleBackend``:

* **No forwarding member.** A *concern object* of a backend is a public attribute its methods assign from a call
  of a class or factory (``self.link = TelloLink(...)``, ``self.signing = make_signing(...)``). A member whose body,
  without its docstring and without calls of the backend's own guard methods (``self._require_navigable(...)``),
  is one statement that calls or returns an attribute of one concern object (``return self.telemetry.position``,
  ``self.offboard.hold()``) or sets one (``self.telemetry.home = value``) only gives that concern a second name:
  callers use the concern (a typed attribute of the contract: ``backend.actions``, ``backend.guidance``) instead.
* **No state property blocks.** The vehicle's state is one :class:`~aerodaas.backends.base.VehicleState` from
  ``state()``; neither a backend nor the contract defines a member named after one of its fields
  (:data:`STATE_FIELDS`).
"""
from __future__ import annotations

import ast
from pathlib import Path

from tests.architecture import sources

ROOT = Path(__file__).resolve().parents[2]
SCANNED = ("aerodaas/backends", "examples/plugins")
#: the fields of VehicleState that once were a property each on every backend
STATE_FIELDS = frozenset({"position", "velocity", "yaw", "roll", "pitch", "armed", "in_air", "battery_pct",
                          "link_ok", "mode", "position_accuracy_m"})


def _classes() -> dict[str, tuple[str, ast.ClassDef]]:
    """Every class of the scanned folders by name: (file relative to the repository, its AST)."""
    out: dict[str, tuple[str, ast.ClassDef]] = {}
    for folder in SCANNED:
        for path in sorted((ROOT / folder).rglob("*.py")):
            for node in ast.walk(sources.tree(path)):
                if isinstance(node, ast.ClassDef):
                    out[node.name] = (str(path.relative_to(ROOT)), node)
    return out


def _base_names(cls: ast.ClassDef) -> list[str]:
    return [b.id if isinstance(b, ast.Name) else b.attr for b in cls.bases if isinstance(b, (ast.Name, ast.Attribute))]


def backend_classes(classes: dict[str, tuple[str, ast.ClassDef]]) -> dict[str, tuple[str, ast.ClassDef]]:
    """The scanned classes deriving from ``VehicleBackend`` (the contract itself excluded)."""
    found = {"VehicleBackend"}
    grew = True
    while grew:
        grew = False
        for name, (_, cls) in classes.items():
            if name not in found and any(b in found for b in _base_names(cls)):
                found.add(name)
                grew = True
    return {n: classes[n] for n in found if n != "VehicleBackend" and n in classes}


def _self_attr(node: ast.AST) -> str | None:
    """``X`` for ``self.X``, else None."""
    if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "self":
        return node.attr
    return None


def _has_factory_call(node: ast.AST) -> bool:
    """A call of a plain name (a class or factory: ``TelloLink(...)``), not of a method (``self.options(cfg)``)."""
    return any(isinstance(n, ast.Call) and isinstance(n.func, ast.Name) for n in ast.walk(node))


def concern_objects(cls: ast.ClassDef) -> set[str]:
    """Public attributes the class's methods assign from a class or factory call."""
    out: set[str] = set()
    for node in ast.walk(cls):
        if isinstance(node, ast.Assign) and _has_factory_call(node.value):
            for target in node.targets:
                for t in (target.elts if isinstance(target, ast.Tuple) else [target]):
                    name = _self_attr(t)
                    if name and not name.startswith("_"):
                        out.add(name)
    return out


def _concern_root(node: ast.AST, concerns: set[str]) -> str | None:
    """The concern ``X`` when ``node`` is ``self.X.<attr>...`` or a call of one, else None."""
    if isinstance(node, ast.Call):
        node = node.func
    if not isinstance(node, ast.Attribute):
        return None
    while isinstance(node.value, ast.Attribute):
        node = node.value
    name = _self_attr(node)
    return name if name in concerns else None


def _is_guard(stmt: ast.stmt) -> bool:
    """A call of the backend's own method as a statement (``self._require_navigable("hold")``)."""
    return (isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Call)
            and _self_attr(stmt.value.func) is not None)


def forwarded_to(fn: ast.FunctionDef, concerns: set[str]) -> str | None:
    """The concern a member only forwards to, or None when it does more."""
    body = list(fn.body)
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
            and isinstance(body[0].value.value, str):
        body = body[1:]
    body = [s for s in body if not _is_guard(s)] or body[-1:]
    if len(body) != 1:
        return None
    stmt = body[0]
    if isinstance(stmt, (ast.Return, ast.Expr)) and stmt.value is not None:
        value = stmt.value
        if isinstance(value, ast.Attribute) and isinstance(value.value, ast.Attribute) or isinstance(value, ast.Call):
            return _concern_root(value, concerns)
    if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 and isinstance(stmt.targets[0], ast.Attribute) \
            and isinstance(stmt.targets[0].value, ast.Attribute):
        return _concern_root(stmt.targets[0], concerns)
    return None


def forwarding_members(cls: ast.ClassDef) -> list[str]:
    """``member -> concern`` for every forwarding member of ``cls``."""
    concerns = concern_objects(cls)
    out = []
    for fn in cls.body:
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            target = forwarded_to(fn, concerns)
            if target is not None:
                out.append(f"{fn.name} -> {target}")
    return out


def state_members(cls: ast.ClassDef) -> list[str]:
    """Members of ``cls`` named after a VehicleState field."""
    return sorted({fn.name for fn in cls.body
                   if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)) and fn.name in STATE_FIELDS})


def test_the_scan_finds_the_backends():
    names = set(backend_classes(_classes()))
    assert {"SimBackend", "MavlinkBackend", "TelloBackend", "ReplayBackend", "RoverBackend",
            "GustySimBackend"} <= names, sorted(names)


def test_no_backend_forwards_to_its_own_concern_objects():
    found = {f"{path}:{name}": fwd for name, (path, cls) in backend_classes(_classes()).items()
             if (fwd := forwarding_members(cls))}
    assert not found, ("members that only call or return an attribute of one of the backend's own concern objects; "
                       f"let callers use the concern (a typed attribute of the contract): {found}")


def test_no_backend_has_a_property_per_state_field():
    classes = _classes()
    found = {f"{path}:{name}": members for name, (path, cls) in [*backend_classes(classes).items(),
                                                                  ("VehicleBackend", classes["VehicleBackend"])]
             if (members := state_members(cls))}
    assert not found, f"the vehicle's state is one VehicleState from state(), not a member per field: {found}"


_OLD_FORM = '''
class Link: ...
class Old(VehicleBackend):
    def __init__(self, cfg):
        self.link = Link(cfg)
        self.cfg = self.options(cfg)
    @property
    def armed(self):
        """the link's"""
        return self.link.armed
    def hold(self):
        self._require_navigable("hold")
        self.link.hold()
    @home.setter
    def home(self, value):
        self.telemetry.home = value
    @property
    def failsafe_action(self):
        return self.cfg.on_failsafe
    def close(self):
        self.link.stop()
        self.link.close()
'''


def test_the_checks_catch_the_old_form():
    """The checks fail on a backend written the old way (a state property that forwards, a guarded command that
    forwards) and pass its settings reads and its members that do more than forward."""
    cls = next(n for n in ast.walk(ast.parse(_OLD_FORM)) if isinstance(n, ast.ClassDef) and n.name == "Old")
    assert concern_objects(cls) == {"link"}
    assert forwarding_members(cls) == ["armed -> link", "hold -> link"]
    assert state_members(cls) == ["armed"]
