"""The built-in actor classes of a run as the record the runtime is handed
(:class:`aerodaas.protocol.actor_classes.ActorClasses`; the runtime itself imports no actor module). Importing this
module imports Ray (the actor classes are ``ray.remote`` classes): entry points import it when a run starts, not
when an application is only loaded (``aerodaas plan``)."""
from __future__ import annotations

from aerodaas.actors.host.analytics_actor import AnalyticsActor, DispatcherActor
from aerodaas.actors.cloud.executor import start_cloud_executors
from aerodaas.actors.host.drone_actor import DroneActor
from aerodaas.actors.builtin.handles import AnalyticsHandle, CameraHandle, DroneHandle, SchedulerHandle
from aerodaas.actors.recording.actor import RecorderActor
from aerodaas.protocol.actor_classes import ActorClasses

__all__ = ["BUILTIN_ACTORS"]

#: the actors and component handles of every run started by ``aerodaas run`` or ``start_mission()``
BUILTIN_ACTORS = ActorClasses(drone=DroneActor, analytics=AnalyticsActor, dispatcher=DispatcherActor,
                              recorder=RecorderActor, start_cloud_executors=start_cloud_executors,
                              drone_handle=DroneHandle, scheduler_handle=SchedulerHandle, camera_handle=CameraHandle,
                              analytics_handle=AnalyticsHandle)
