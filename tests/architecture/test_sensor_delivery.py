"""The runtime asks a sensor how its data is delivered; it never tests the sensor's class.

A sensor type's class names the component of the drone's actor that delivers its data (its ``delivery``, a
:class:`aerodaas.plugins.sensor.Delivery` member); the runtime reads that member. Parses every ``.py`` file of
``aerodaas/runtime/``, ``aerodaas/reliability/``, ``aerodaas/backends/`` and ``actors/`` with :mod:`ast` and lists
every ``issubclass(...)`` / ``isinstance(...)`` whose class argument (or an element of a tuple of them) is a sensor
class of :mod:`aerodaas.plugins.sensor` or :mod:`aerodaas.plugins.builtin_sensors` (the contracts and the
built-ins), by its name, an alias it was imported under, or an attribute of that name (``sensor.FrameSensor``).
The one place that maps a delivery to what it means, :class:`~aerodaas.plugins.sensor.Delivery`, lives outside
these folders, so the allow-list is empty.
"""
from __future__ import annotations

import ast
import inspect
from pathlib import Path

import aerodaas.plugins.builtin_sensors as builtin_sensors
import aerodaas.plugins.sensor as sensor

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("aerodaas/runtime", "aerodaas/reliability", "aerodaas/backends", "actors")

#: (path relative to the repository root, the call as ``ast.unparse`` prints it) -> why it may test the class
ALLOWED: dict[tuple[str, str], str] = {}


def _sensor_class_names() -> frozenset[str]:
    """Names of every SensorPlugin subclass (and SensorPlugin) defined in the sensor and built-in sensor modules."""
    names = set()
    for mod in (sensor, builtin_sensors):
        for name, obj in vars(mod).items():
            if inspect.isclass(obj) and issubclass(obj, sensor.SensorPlugin) and obj.__module__ == mod.__name__:
                names.add(name)
    return frozenset(names)


SENSOR_CLASSES = _sensor_class_names()


def class_tests(source: str) -> list[str]:
    """The ``issubclass``/``isinstance`` calls of ``source`` against a sensor class, as ``ast.unparse`` prints them."""
    tree = ast.parse(source)
    aliases = {a.asname or a.name: a.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
               and (node.module or "").startswith("aerodaas.plugins") for a in node.names}

    def names_a_sensor_class(node: ast.expr) -> bool:
        if isinstance(node, ast.Tuple):
            return any(names_a_sensor_class(e) for e in node.elts)
        if isinstance(node, ast.Name):
            return aliases.get(node.id, node.id) in SENSOR_CLASSES
        return isinstance(node, ast.Attribute) and node.attr in SENSOR_CLASSES

    return [ast.unparse(node) for node in ast.walk(tree)
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id in ("issubclass", "isinstance") and len(node.args) == 2
            and names_a_sensor_class(node.args[1])]


def test_the_contracts_and_builtins_are_found():
    assert {"SensorPlugin", "ActorProducedSensor", "FrameSensor", "VehicleStateSensor",
            "MissionStatusSensor", "CameraSensor", "OdometrySensor", "StatStreamSensor"} <= SENSOR_CLASSES


def test_the_check_finds_a_class_test_however_the_class_is_named():
    src = ("from aerodaas.plugins.sensor import FrameSensor as FS\nimport aerodaas.plugins.sensor as s\n"
           "a = issubclass(c, FS)\nb = isinstance(x, (int, s.MissionStatusSensor))\n"
           "c = issubclass(c, CameraSensor)\nd = issubclass(c, int)\ne = c.delivery.frames\n")
    assert class_tests(src) == ["issubclass(c, FS)", "isinstance(x, (int, s.MissionStatusSensor))",
                                "issubclass(c, CameraSensor)"]


def test_no_runtime_module_tests_a_sensor_class():
    found = []
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            found += [f"{rel}: {call}" for call in class_tests(path.read_text(encoding="utf-8"))
                      if (rel, call) not in ALLOWED]
    assert not found, ("the runtime tests a sensor's class instead of asking its `delivery` "
                       "(aerodaas.plugins.sensor.Delivery):\n" + "\n".join(found))
