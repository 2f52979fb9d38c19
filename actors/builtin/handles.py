"""The driver's typed handles to components inside the run's actors.

A component (a drone, its navigation inbox, a camera, an analytics instance) lives in one of the run's Ray
actors; the driver, the HITL API and the application reach it through that actor's
:meth:`~aerodaas.actors.host.base.ActorBase.call`, which takes the component id and the component class's method
itself (a function, pickled by reference), never a method name. Each handle class lists the methods it offers as
:class:`remote_method` attributes, used like an actor handle's: ``h.status.remote()`` returns the ObjectRef of
``DroneComponent.status()`` run in the drone's actor. A misspelt method is an AttributeError here, in the driver,
before anything is sent.
"""
from __future__ import annotations

from aerodaas.actors.analytics.component import AnalyticsComponent
from aerodaas.actors.sensors.camera import CameraComponent
from aerodaas.actors.drone.component import DroneComponent
from aerodaas.actors.drone.scheduler_component import SchedulerComponent
from aerodaas.protocol.handles import ComponentHandle, remote_method

__all__ = ["remote_method", "ComponentHandle", "DroneHandle", "SchedulerHandle", "CameraHandle", "AnalyticsHandle"]


class DroneHandle(ComponentHandle):
    """A drone component (:class:`~aerodaas.actors.drone.component.DroneComponent`)."""

    status = remote_method(DroneComponent.status)
    report = remote_method(DroneComponent.report)
    pause_mission = remote_method(DroneComponent.pause_mission)
    resume_mission = remote_method(DroneComponent.resume_mission)
    end_mission = remote_method(DroneComponent.end_mission)
    point_gimbal = remote_method(DroneComponent.point_gimbal)
    gimbal_attitude = remote_method(DroneComponent.gimbal_attitude)


class SchedulerHandle(ComponentHandle):
    """A robot's navigation inbox (:class:`~aerodaas.actors.drone.scheduler_component.SchedulerComponent`; in a run the
    drone's own :class:`~aerodaas.actors.drone.inbox.DroneInbox`, which has the drone apply what it adds at once):
    the drone's waypoint queue (``snapshot``), navigation added and cleared through the HITL API."""

    snapshot = remote_method(SchedulerComponent.snapshot)
    add_navigation = remote_method(SchedulerComponent.add_navigation)
    clear_navigation = remote_method(SchedulerComponent.clear_navigation)
    stats = remote_method(SchedulerComponent.stats)


class CameraHandle(ComponentHandle):
    """A camera component (:class:`~aerodaas.actors.sensors.camera.CameraComponent`)."""

    get_latest = remote_method(CameraComponent.get_latest)
    stats = remote_method(CameraComponent.stats)


class AnalyticsHandle(ComponentHandle):
    """An analytics instance (:class:`~aerodaas.actors.analytics.component.AnalyticsComponent`)."""

    get_latest = remote_method(AnalyticsComponent.get_latest)
    stats = remote_method(AnalyticsComponent.stats)
