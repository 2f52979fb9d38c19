"""DroneInbox: a drone's own navigation port. The robot's :class:`~aerodaas.actors.drone.scheduler_component.SchedulerComponent`
(checks, plans with the trajectory scheduler plug-in, commits into the drone's waypoint queue) made part of the drone:
what it takes the drone applies to the vehicle at once, not at its next control tick.

The drone builds its inbox (:class:`~aerodaas.actors.drone.component.DroneComponent`, ``inbox``) around its own queue and
mission plan log and hands it a :class:`DronePort`: the two things the inbox needs of the drone, as callables. The
actor's assembly registers the inbox under the robot's scheduler component id (``<robot>/scheduler``), where analytics
streams deliver navigation on its ``priority`` port and the HITL API calls it. Edges run one way: the drone knows its
inbox; the inbox knows only its port (where the drone was at its last control tick, and "apply what I took now"),
never the drone object nor its class. Nothing on the scheduler side (the inbox's base class, the plug-in, the queue)
knows a drone.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from aerodaas.navigation.waypoint_queue import WaypointQueue
from aerodaas.protocol.messages import Message, Port

from aerodaas.actors.drone.mission_plan import MissionPlanLog
from aerodaas.actors.drone.scheduler_component import SchedulerComponent


@dataclass(frozen=True)
class DronePort:
    """What a drone's inbox needs of its drone, handed over by the drone when it builds the inbox:
    ``last_tick()`` returns the drone's vehicle time (s) and position (ENU metres) at its last control tick, where
    new navigation is checked and planned from; ``apply()`` has the drone apply newly queued navigation now and
    returns True when the drone was in a state that flies navigation (the command reached the backend or was
    refused by the safety gate)."""

    last_tick: Callable[[], tuple[float, tuple]]
    apply: Callable[[], bool]


class DroneInbox(SchedulerComponent):
    """A drone's navigation port: fills the drone's ``queue`` and shares its ``log`` (other arguments as
    :class:`SchedulerComponent`); ``port`` is what it needs of the drone (:class:`DronePort`). New navigation is
    applied by the drone at once; the latency record's ``applied`` says whether the drone was in a state that flies
    navigation."""

    def __init__(self, plane: Any, cid: str, robot_id: str, scheduler: Any, recorder: Any, epoch_ns: int,
                 robot_cfg: dict | None, queue: WaypointQueue, log: MissionPlanLog, port: DronePort) -> None:
        super().__init__(plane, cid, robot_id, scheduler, recorder, epoch_ns, robot_cfg, queue=queue, log=log)
        self.drone_port = port

    def where(self) -> tuple[float, tuple]:
        """The drone's simulated time (s) and position (ENU metres) at its last control tick."""
        return self.drone_port.last_tick()

    def handle(self, port: Port, msg: Message) -> None:
        """Take the navigation (see :meth:`SchedulerComponent.take`) and have the drone apply it now."""
        if self.take(port, msg):
            self.record_latency(msg, applied=self.drone_port.apply())
        return None

    def add_navigation(self, nav: Any, index: int | None = None, priority: int | None = None) -> dict:
        """:meth:`SchedulerComponent.add_navigation`, then the drone applies it now. Raises as that method (and
        then nothing is queued nor applied)."""
        out = super().add_navigation(nav, index, priority)
        self.drone_port.apply()
        return out
