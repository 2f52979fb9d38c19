"""The driver's typed handles to components inside the run's actors.

A component (a drone, its navigation inbox, a camera, an analytics instance) lives in one of the run's Ray
actors; the driver, the HITL API and the application reach it through that actor's
:meth:`~aerodaas.actors.actor_base.ActorBase.call`, which takes the component id and the component class's method
itself (a function, pickled by reference), never a method name. Each handle class lists the methods it offers as
:class:`remote_method` attributes, used like an actor handle's: ``h.status.remote()`` returns the ObjectRef of
``DroneComponent.status()`` run in the drone's actor. A misspelt method is an AttributeError here, in the driver,
before anything is sent.
"""
from __future__ import annotations

from typing import Any, Callable

from aerodaas.actors.analytics_component import AnalyticsComponent
from aerodaas.actors.camera import CameraComponent
from aerodaas.actors.drone import DroneComponent
from aerodaas.actors.scheduler_component import SchedulerComponent

__all__ = ["remote_method", "ComponentHandle", "DroneHandle", "SchedulerHandle", "CameraHandle", "AnalyticsHandle"]


class _BoundCall:
    """``method`` of component ``cid`` in ``actor`` (its Ray handle): :meth:`remote` calls it there."""

    __slots__ = ("actor", "cid", "method")

    def __init__(self, actor: Any, cid: str, method: Callable) -> None:
        self.actor, self.cid, self.method = actor, cid, method

    def remote(self, *args: Any, **kwargs: Any) -> Any:
        """Call the method in the component's actor; returns the call's ObjectRef."""
        return self.actor.call.remote(self.cid, self.method, *args, **kwargs)

    def __repr__(self) -> str:
        return f"<{self.method.__qualname__} of component {self.cid!r}>"


class remote_method:  # noqa: N801 - used like a decorator/descriptor, as Ray's own ``ray.method``
    """A public method of a component class, called in the component's actor through a handle (a descriptor on
    :class:`ComponentHandle` subclasses). Raises TypeError for a private name."""

    def __init__(self, method: Callable) -> None:
        if method.__name__.startswith("_"):
            raise TypeError(f"{method.__qualname__} is not a public component method")
        self.method = method

    def __get__(self, handle: Any, owner: type | None = None) -> Any:
        if handle is None:
            return self
        return _BoundCall(handle.actor, handle.cid, self.method)


class ComponentHandle:
    """A component inside one of the run's actors (``actor``: that actor's handle; ``cid``: the component id).
    Subclasses declare the component's methods the driver may call (:class:`remote_method`)."""

    def __init__(self, actor: Any, cid: str) -> None:
        self.actor, self.cid = actor, cid

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.cid!r})"


class DroneHandle(ComponentHandle):
    """A drone component (:class:`~aerodaas.actors.drone.DroneComponent`)."""

    status = remote_method(DroneComponent.status)
    report = remote_method(DroneComponent.report)
    pause_mission = remote_method(DroneComponent.pause_mission)
    resume_mission = remote_method(DroneComponent.resume_mission)
    end_mission = remote_method(DroneComponent.end_mission)
    point_gimbal = remote_method(DroneComponent.point_gimbal)
    gimbal_attitude = remote_method(DroneComponent.gimbal_attitude)


class SchedulerHandle(ComponentHandle):
    """A robot's navigation inbox (:class:`~aerodaas.actors.scheduler_component.SchedulerComponent`; in a run the
    drone's own :class:`~aerodaas.actors.drone_inbox.DroneInbox`, which has the drone apply what it adds at once):
    the drone's waypoint queue (``snapshot``), navigation added and cleared through the HITL API."""

    snapshot = remote_method(SchedulerComponent.snapshot)
    add_navigation = remote_method(SchedulerComponent.add_navigation)
    clear_navigation = remote_method(SchedulerComponent.clear_navigation)
    stats = remote_method(SchedulerComponent.stats)


class CameraHandle(ComponentHandle):
    """A camera component (:class:`~aerodaas.actors.camera.CameraComponent`)."""

    get_latest = remote_method(CameraComponent.get_latest)
    stats = remote_method(CameraComponent.stats)


class AnalyticsHandle(ComponentHandle):
    """An analytics instance (:class:`~aerodaas.actors.analytics_component.AnalyticsComponent`)."""

    get_latest = remote_method(AnalyticsComponent.get_latest)
    stats = remote_method(AnalyticsComponent.stats)
