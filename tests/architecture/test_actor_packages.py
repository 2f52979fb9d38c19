"""Layers inside ``aerodaas.actors``: ``actors/`` is laid out by concept, one sub-package each, with no module left
flat beside them; imports between those sub-packages go down :data:`ACTOR_LAYERS` only; and inside the drone the
edges run one way: the drone builds its parts (inbox, flights, deadlines, gimbal, odometry, end of run) and hands
each what it needs, as values, callables or a small typed port; no part imports the drone's class or holds the
drone object. The import reader is :mod:`tests.architecture.test_layers`' (imports in functions and under
``TYPE_CHECKING`` count). No Ray: the drone of the last test flies the simulator stepped by hand."""
from __future__ import annotations

import ast
import dataclasses
from collections import defaultdict

from aerodaas.backends.sim import SimBackend
from aerodaas.config import RobotConfig
from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.navigation.fsm import MissionState as S

from tests.architecture.test_layers import MODULES, ROOT, imports_of

ACTORS = ROOT / "actors"
#: the sub-packages of ``aerodaas.actors``, bottom (0) to top; an import between two of them goes to a lower line
ACTOR_LAYERS = {
    "data": 0,  # the data plane in one actor and its transports (same-node channel, Ray route, frame copies)
    "drone": 1, "sensors": 1, "analytics": 1, "recording": 1,  # the components an actor hosts; none knows another
    "dispatch": 2,  # the analytics scheduler's side of a dispatcher actor (its analytics are analytics components)
    "host": 3,  # ActorBase, the assembly that builds an actor's components, the Ray actor classes built on it
    "cloud": 4,  # the cloud executor actors (Ray plumbing from host)
    "builtin": 5,  # the record of actor classes and component handles the runtime is handed
}
#: the drone's module that defines the drone (:class:`~aerodaas.actors.drone.component.DroneComponent`)
DRONE = "aerodaas.actors.drone.component"


def actor_package(module: str) -> str | None:
    """``"drone"`` for ``aerodaas.actors.drone.inbox``; None for ``aerodaas.actors`` itself and outside it."""
    parts = module.split(".")
    return parts[2] if parts[:2] == ["aerodaas", "actors"] and len(parts) > 2 else None


def actor_edges() -> dict[tuple[str, str], list[str]]:
    """(importing sub-package, imported sub-package) → the edges that make it (``"module:line -> target"``)."""
    edges: dict[tuple[str, str], list[str]] = defaultdict(list)
    for mod, path in MODULES.items():
        src = actor_package(mod)
        if src is None:
            continue
        for target, line in imports_of(mod, path):
            dst = actor_package(target)
            if dst is not None and dst != src:
                edges[(src, dst)].append(f"{mod}:{line} -> {target}")
    return dict(edges)


def test_no_module_is_left_flat_in_actors():
    """Every module of ``actors/`` is in a concept's sub-package (a folder with ``__init__.py``); the top holds only
    ``__init__.py``, which imports nothing."""
    flat = sorted(p.name for p in ACTORS.glob("*.py") if p.name != "__init__.py")
    assert not flat, f"modules flat in actors/ (move each into its concept's sub-package): {flat}"
    loose = sorted(str(p.relative_to(ROOT)) for p in ACTORS.rglob("*.py") if not (p.parent / "__init__.py").is_file())
    assert not loose, f"modules in a folder of actors/ without __init__.py: {loose}"
    assert not imports_of("aerodaas.actors", ACTORS / "__init__.py")


def test_every_actor_sub_package_has_its_layer():
    found = {p.parent.name for p in ACTORS.glob("*/__init__.py")}
    assert found == set(ACTOR_LAYERS), (f"sub-packages of actors/ without a layer: {sorted(found - set(ACTOR_LAYERS))}; "
                                        f"layers without a sub-package: {sorted(set(ACTOR_LAYERS) - found)}")


def test_imports_between_actor_sub_packages_go_down():
    """The drone, a sensor, an analytics and the recording are components side by side: none imports another
    (the drone never reaches into the recorder's internals: it is handed a recorder); the data plane is below them
    all, the host (which builds every component) above them, the built-in catalogue on top."""
    edges = actor_edges()
    assert ("host", "drone") in edges and ("drone", "data") in edges  # the reader sees the edges
    bad = [f"{a} ({ACTOR_LAYERS[a]}) -> {b} ({ACTOR_LAYERS[b]}): {e}" for (a, b), es in sorted(edges.items())
           if ACTOR_LAYERS[b] >= ACTOR_LAYERS[a] for e in es]
    assert not bad, "imports between sub-packages of aerodaas.actors that do not go down ACTOR_LAYERS:\n" + "\n".join(bad)


def _names_the_drone_class(path) -> list[int]:
    """Lines of ``path`` whose code (not docstrings) names ``DroneComponent``: a name, an attribute, an imported
    name or a string annotation."""
    lines = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Name) and node.id == "DroneComponent" \
                or isinstance(node, ast.Attribute) and node.attr == "DroneComponent" \
                or isinstance(node, ast.alias) and node.name == "DroneComponent":
            lines.append(node.lineno)
        for ann in (getattr(node, "annotation", None), getattr(node, "returns", None)):
            if isinstance(ann, ast.Constant) and isinstance(ann.value, str) and "DroneComponent" in ann.value:
                lines.append(ann.lineno)
    return lines


def test_the_drones_parts_do_not_import_the_drone():
    """No module of the drone's package but the drone's own imports it (in functions and under ``TYPE_CHECKING``
    included) or names its class: its inbox and flights are handed what they need."""
    parts = {m: p for m, p in MODULES.items() if m.startswith("aerodaas.actors.drone.") and m != DRONE}
    assert {"aerodaas.actors.drone.inbox", "aerodaas.actors.drone.queue_flight"} <= set(parts)
    bad = [f"{m}:{line} imports {t}" for m, p in parts.items() for t, line in imports_of(m, p)
           if t == DRONE or t.startswith(DRONE + ".")]
    bad += [f"{m}:{line} names DroneComponent" for m, p in parts.items() for line in _names_the_drone_class(p)]
    assert not bad, "parts of the drone that know the drone:\n" + "\n".join(bad)
    assert _names_the_drone_class(MODULES["aerodaas.actors.host.assembly"])  # the reader finds a real use


def test_the_reader_finds_a_back_reference(tmp_path):
    f = tmp_path / "part.py"
    f.write_text('"""A DroneComponent in prose is fine."""\n'
                 "def f(d: 'DroneComponent') -> None:\n"
                 "    from aerodaas.actors.drone.component import DroneComponent\n")
    assert _names_the_drone_class(f) == [2, 3]
    assert (DRONE, 3) in imports_of("aerodaas.actors.drone.part", f)


class _Recorded:
    """The recorder calls a drone makes, dropped."""

    def json(self, *args, **kwargs) -> None:
        pass

    def odometry(self, *args, **kwargs) -> None:
        pass


def _held(obj, depth: int = 2):
    """Every value ``obj`` holds: its attributes (``__dict__``, a dataclass's fields) and, down to ``depth``, what
    the values of the drone's own package hold in turn (a flight's context, the inbox's port). Callables are values
    too: a bound method of the drone is what a part is handed, not the drone."""
    values = list(vars(obj).values()) if hasattr(obj, "__dict__") else []
    if dataclasses.is_dataclass(obj) and not hasattr(obj, "__dict__"):
        values = [getattr(obj, f.name) for f in dataclasses.fields(obj)]
    out = list(values)
    if depth > 0:
        for v in values:
            if type(v).__module__.startswith("aerodaas.actors.drone."):
                out += _held(v, depth - 1)
    return out


def test_no_part_of_a_flying_drone_holds_the_drone():
    """A drone flying the simulator: none of its parts (the inbox, its port, the flights and their context, the
    deadlines, the gimbal, the odometry, the end of run) holds the drone object; the inbox still reads where the
    drone is and has the drone apply what it takes at once (the drone's ``nudges``)."""
    from aerodaas.actors.drone.component import DroneComponent
    from aerodaas.schedulers.base import TrajectoryScheduler

    cfg = RobotConfig.model_validate({"id": "d", "takeoff_altitude": 4.0})
    sched = TrajectoryScheduler()
    sched.add_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="w1", x=20.0, y=0.0, z=4.0)],
                                        SchedulingType.ORDERED))
    d = DroneComponent("d/drone", cfg.model_dump(mode="json"), None, sched, _Recorded(), 0, 1, [], [],
                       backend=SimBackend(cfg))
    d.start()
    while d.backend.t < 60.0 and d.fsm.state not in (S.NAVIGATING, S.WAYPOINT_HOLD):
        d.step(0.1)
        d.control_tick()
    assert d.fsm.state in (S.NAVIGATING, S.WAYPOINT_HOLD), d.fsm.state
    parts = {name: v for name, v in vars(d).items() if type(v).__module__.startswith("aerodaas.actors.drone.")}
    assert {"inbox", "queue_flight", "autopilot_flight", "deadlines", "gimbal", "odometry", "end"} <= set(parts)
    holding = sorted(name for name, part in parts.items() if any(v is d for v in _held(part)))
    assert not holding, f"parts of the drone that hold the drone object: {holding}"
    assert d.inbox.where() == d.last_tick
    nudges = d.nudges
    d.inbox.add_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="w2", x=0.0, y=20.0, z=4.0)],
                                          SchedulingType.ORDERED))
    assert d.nudges == nudges + 1
