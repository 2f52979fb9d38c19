"""What each robot of a run plan flies with: its vehicle backend and trajectory scheduler, each
with its registered name and origin, and every sensor it has, also those that feed nothing and so are no component
of the plan's graph (an odometry sensor nobody subscribes to: the drone actor records the vehicle state anyway).

Origins are those of ``aerodaas plugins`` (:mod:`aerodaas.plugins.registry`): ``builtin``, ``decorator in FILE``,
``import path MODULE:CLASS``, ``entry point DIST``; a trajectory scheduler class the application built without
registering it is ``unregistered class in FILE`` (:func:`aerodaas.plugins.registry.class_origin`).
:class:`aerodaas.runtime.dataflow.RunPlan` holds one :class:`RobotUse` per robot and prints them in
``aerodaas plan`` (text and ``--json``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from aerodaas.plugins import registry
from aerodaas.plugins.registry import class_origin
from aerodaas.plugins.sensor import Delivery
from aerodaas.protocol.ids import ComponentId

__all__ = ["PluginUse", "SensorUse", "RobotUse", "robot_uses"]


@dataclass(frozen=True)
class PluginUse:
    """One plug-in a robot uses: ``name`` (its registered name), ``origin`` (see the module docstring) and ``cls``
    (``module:qualname`` of the class the run builds)."""

    name: str
    origin: str
    cls: str

    def describe(self) -> dict[str, str]:
        """``{"name", "origin", "class"}``."""
        return {"name": self.name, "origin": self.origin, "class": self.cls}


@dataclass(frozen=True)
class SensorUse:
    """One sensor of a robot: ``id``, ``type`` (``sensors[].type``), its plug-in ``origin``, ``delivery`` (the
    component of the drone actor that delivers its data: the sensor class's
    :attr:`~aerodaas.plugins.sensor.SensorPlugin.delivery`) and ``component``: its
    component id in the plan's graph, None when it feeds nothing and is not a camera or plug-in sensor."""

    id: str
    type: str
    origin: str
    delivery: Delivery
    component: str | None

    def describe(self) -> dict[str, Any]:
        """``{"id", "type", "origin", "delivery", "component"}`` (``delivery``: the :class:`Delivery`'s value)."""
        return {"id": self.id, "type": self.type, "origin": self.origin, "delivery": self.delivery.value,
                "component": self.component}


@dataclass(frozen=True)
class RobotUse:
    """A robot's ``backend``, ``scheduler`` (its trajectory scheduler) and ``sensors`` (in configuration order)."""

    robot: str
    backend: PluginUse
    scheduler: PluginUse
    sensors: tuple[SensorUse, ...]

    def describe(self) -> dict[str, Any]:
        """A JSON-ready description: ``{"id", "backend", "trajectory_scheduler", "sensors"}``."""
        return {"id": self.robot, "backend": self.backend.describe(), "trajectory_scheduler": self.scheduler.describe(),
                "sensors": [s.describe() for s in self.sensors]}

    def text(self) -> list[str]:
        """Lines for ``aerodaas plan``: the backend, the trajectory scheduler, one line per sensor."""
        b, s = self.backend, self.scheduler
        lines = [f"  robot {self.robot}: backend {b.name} ({b.origin}), trajectory scheduler {s.name} ({s.origin})"]
        for x in self.sensors:
            where = f"component {x.component}" if x.component else "no component (nothing subscribes)"
            lines.append(f"      sensor {x.id:<12} {x.type} ({x.origin}), {x.delivery.value}, {where}")
        return lines


def _use(kind: str, cls: type, name: str | None = None, origin: str | None = None) -> PluginUse:
    if name is None or origin is None:
        name, origin = class_origin(kind, cls)
    return PluginUse(name, origin, f"{cls.__module__}:{cls.__qualname__}")


def robot_uses(robots: list, scheds: dict[str, Any], components: set[str]) -> dict[str, RobotUse]:
    """Robot id -> its :class:`RobotUse`. ``robots``: the run's robots (:class:`aerodaas.app.api.Robot`, with
    ``cfg`` and ``sensors``); ``scheds``: robot id -> its trajectory scheduler object; ``components``: the ids of
    the plan's nodes. Raises :class:`aerodaas.plugins.registry.UnknownPlugin` for a backend or sensor type that is
    not registered (refused earlier, when the configuration was validated)."""
    from aerodaas.config.robot import sensor_class  # lazy: heavy numpy, pymap3d, shapely

    out: dict[str, RobotUse] = {}
    for r in robots:
        be = registry.resolve("backend", r.cfg.backend)
        sensors = []
        for s in r.sensors.values():
            e, scls = registry.resolve("sensor", s.type), sensor_class(s.type)
            cid = ComponentId.sensor(r.id, s.id, scls.component_kind)
            sensors.append(SensorUse(s.id, s.type, e.origin, scls.delivery,
                                     cid if cid in components else None))
        out[r.id] = RobotUse(r.id, _use("backend", be.load(), be.name, be.origin),
                             _use("trajectory_scheduler", type(scheds[r.id])), tuple(sensors))
    return out
