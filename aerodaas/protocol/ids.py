"""Component ids: the name of one component of a run (a node of the :class:`~aerodaas.runtime.dataflow.RunPlan`),
typed.

A :class:`ComponentId` is a ``str`` (so it is a dict key, a Ray argument and a JSON value as before: ``d1/drone``,
``d1/scheduler``, ``d1/cam``, ``detector#1``, ``follow#2@d1``) that also says what the component is (``kind``)
and which robot it belongs to (``robot``, None for a shared analytics). Code that needs to know whether a component
is a drone asks ``cid.kind``, never the spelling of the id.
"""
from __future__ import annotations

from typing import Any, Literal

__all__ = ["ComponentKind", "ComponentId", "is_drone"]

#: what a component is (the node kinds of :class:`~aerodaas.runtime.dataflow.Node`)
ComponentKind = Literal["drone", "camera", "odometry", "stat_stream", "sensor", "scheduler", "analytics"]


class ComponentId(str):
    """The id of a component (see the module docstring). ``ComponentId("d1/drone", "drone", "d1")``; the
    constructors :meth:`drone`, :meth:`scheduler` and :meth:`sensor` spell the ids of a robot's own components.
    Equal to (and hashed like) the plain string, so ids read from older wiring or typed by a user still match.
    Pickles with its kind and robot (it travels to the actors in the plan)."""

    kind: ComponentKind
    robot: str | None

    def __new__(cls, value: str, kind: ComponentKind, robot: str | None = None) -> "ComponentId":
        self = super().__new__(cls, value)
        self.kind, self.robot = kind, robot
        return self

    def __reduce__(self) -> tuple[Any, ...]:
        return (ComponentId, (str(self), self.kind, self.robot))

    def __repr__(self) -> str:
        return f"ComponentId({str(self)!r}, kind={self.kind!r})"

    @classmethod
    def drone(cls, robot: str) -> "ComponentId":
        """The drone component of robot ``robot``: ``<robot>/drone``."""
        return cls(f"{robot}/drone", "drone", robot)

    @classmethod
    def scheduler(cls, robot: str) -> "ComponentId":
        """The trajectory scheduler of robot ``robot``: ``<robot>/scheduler``."""
        return cls(f"{robot}/scheduler", "scheduler", robot)

    @classmethod
    def sensor(cls, robot: str, sensor: str, kind: ComponentKind) -> "ComponentId":
        """Sensor ``sensor`` of robot ``robot`` (``kind``: camera, odometry or stat_stream): ``<robot>/<sensor>``."""
        return cls(f"{robot}/{sensor}", kind, robot)


def is_drone(cid: Any) -> bool:
    """True when ``cid`` is the :class:`ComponentId` of a drone component."""
    return isinstance(cid, ComponentId) and cid.kind == "drone"
