"""DroneInbox: a drone's own navigation port. The robot's :class:`~aerodaas.actors.drone.scheduler_component.SchedulerComponent`
(checks, plans with the trajectory scheduler plug-in, commits into the drone's waypoint queue) made part of the drone:
what it takes the drone applies to the vehicle at once, not at its next control tick.

The drone builds its inbox (:class:`~aerodaas.actors.drone.component.DroneComponent`, ``inbox``) around its own queue and
mission plan log; the actor's assembly registers it under the robot's scheduler component id (``<robot>/scheduler``),
where analytics streams deliver navigation on its ``priority`` port and the HITL API calls it. Calls go one way:
the inbox reads where its drone was at its last control tick and hands what it took to the drone
(:meth:`~aerodaas.actors.drone.component.DroneComponent.apply_navigation`); the drone flies from its own queue and never
calls the inbox. Nothing on the scheduler side (the inbox's base class, the plug-in, the queue) knows a drone.
"""
from __future__ import annotations

from typing import Any

from aerodaas.navigation.waypoint_queue import WaypointQueue
from aerodaas.protocol.messages import Message, Port

from aerodaas.actors.drone.mission_plan import MissionPlanLog
from aerodaas.actors.drone.scheduler_component import SchedulerComponent


class DroneInbox(SchedulerComponent):
    """The navigation port of ``drone`` (a :class:`~aerodaas.actors.drone.component.DroneComponent`, whose ``queue`` it fills
    and whose ``plan_log`` it shares; other arguments as :class:`SchedulerComponent`). New navigation is applied by the drone at once; the latency
    record's ``applied`` says whether the drone was in a state that flies navigation."""

    def __init__(self, plane: Any, cid: str, robot_id: str, scheduler: Any, recorder: Any, epoch_ns: int,
                 robot_cfg: dict | None, queue: WaypointQueue, log: MissionPlanLog, drone: Any) -> None:
        super().__init__(plane, cid, robot_id, scheduler, recorder, epoch_ns, robot_cfg, queue=queue, log=log)
        self.owner = drone

    def where(self) -> tuple[float, tuple]:
        """The drone's simulated time (s) and position (ENU metres) at its last control tick."""
        return self.owner.last_tick

    def handle(self, port: Port, msg: Message) -> None:
        """Take the navigation (see :meth:`SchedulerComponent.take`) and have the drone apply it now."""
        if self.take(port, msg):
            self.record_latency(msg, applied=self.owner.apply_navigation())
        return None

    def add_navigation(self, nav: Any, index: int | None = None, priority: int | None = None) -> dict:
        """:meth:`SchedulerComponent.add_navigation`, then the drone applies it now. Raises as that method (and
        then nothing is queued nor applied)."""
        out = super().add_navigation(nav, index, priority)
        self.owner.apply_navigation()
        return out
