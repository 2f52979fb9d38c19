"""The actor classes a run is made of, as one typed record the entry point hands the runtime.

The runtime (:mod:`aerodaas.runtime`) starts the run's actors and binds the driver's handles to their components,
but imports no module of :mod:`aerodaas.actors` (``tests/architecture/test_layers.py`` checks it): whoever starts a run — the
application API's ``start_mission()``, ``aerodaas run``, a test's ``run_options`` fixture — puts the classes on
:attr:`aerodaas.runtime.options.RunOptions.actors`. The built-in record is
:data:`aerodaas.actors.builtin.catalogue.BUILTIN_ACTORS`; a test or benchmark may hand other classes with the same
constructor and method contract. An entry point that should not import the actor modules (and with them Ray and
OpenCV) before the application is checked hands an :class:`ActorClassesSource` instead: the runtime loads it once the
run's input passed its checks (``aerodaas run`` reports a bad application in about 0.5 s less that way).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Mapping, Protocol

from aerodaas.protocol.handles import ComponentHandle
from aerodaas.protocol.specs import Role

__all__ = ["ActorClasses", "ActorClassesSource", "RayActorClass", "CloudExecutorStarter"]


class RayActorClass(Protocol):
    """What ``ray.remote`` makes of a class (or :class:`aerodaas.actors.host.remote.LazyActorClass`): ``options(...)``
    returns a copy with Ray's actor options (``name``, ``label_selector``, ``max_restarts``,
    ``scheduling_strategy``); ``remote(*args)`` creates the actor and returns its handle."""

    def options(self, **options: Any) -> Any: ...

    def remote(self, *args: Any, **kwargs: Any) -> Any: ...


class CloudExecutorStarter(Protocol):
    """Starts ``n`` cloud executor actors (:func:`aerodaas.actors.cloud.executor.start_cloud_executors`) placed with
    ``selector`` and named ``<ray_name_prefix><i>`` in Ray, running copies of ``analytics`` (name -> analytics);
    returns their handles once each answered. Raises ValueError for ``n < 1``."""

    def __call__(self, n: int, mode: str = ..., *, selector: Mapping[str, str] | None = ...,
                 name_prefix: str = ..., analytics: Mapping[str, Any] | None = ...,
                 ray_name_prefix: str | None = ...) -> list: ...


@dataclass(frozen=True)
class ActorClasses:
    """The Ray actor classes of a run, per plan role (``drone``, ``analytics``, ``dispatcher``, ``recorder``: the
    constructors the runtime calls are ``(host id, tier)`` for the first three and ``(ActorSpec)`` for the
    recorder), the starter of the analytics scheduler's cloud executors, and the driver's component handle classes
    (each constructed as ``(actor handle, component id)``)."""

    drone: RayActorClass
    analytics: RayActorClass
    dispatcher: RayActorClass
    recorder: RayActorClass
    start_cloud_executors: CloudExecutorStarter
    drone_handle: type[ComponentHandle]
    scheduler_handle: type[ComponentHandle]
    camera_handle: type[ComponentHandle]
    analytics_handle: type[ComponentHandle]

    def for_role(self, role: Role) -> RayActorClass:
        """The actor class of a plan role. Raises ValueError for a role without one."""
        classes: dict[str, RayActorClass] = {"drone": self.drone, "analytics": self.analytics,
                                             "dispatcher": self.dispatcher, "recorder": self.recorder}
        if role not in classes:
            raise ValueError(f"no actor class for role {role!r} (roles: {sorted(classes)})")
        return classes[role]


class ActorClassesSource(ABC):
    """Where a run's :class:`ActorClasses` come from when they are imported only as the run starts: the runtime calls
    :meth:`load` after the application and the run's options passed their checks (bad input is reported without
    importing the actor modules) and before Ray starts. The built-in source is
    :data:`aerodaas.actors.builtin.source.BUILTIN`."""

    @abstractmethod
    def load(self) -> ActorClasses:
        """The run's actor classes (imports the modules that define them). Raises what that import raises."""
