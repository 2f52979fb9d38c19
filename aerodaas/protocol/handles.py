"""The driver's handle to a component inside one of the run's actors, below both the runtime and the actors.

A component (a drone, its navigation inbox, a camera, an analytics instance) lives in one of the run's Ray
actors; the driver, the HITL API and the application reach it through that actor's
:meth:`~aerodaas.actors.host.base.ActorBase.call`, which takes the component id and the component class's method
itself (a function, pickled by reference), never a method name. :class:`ComponentHandle` is the base of the
concrete handles (:mod:`aerodaas.actors.builtin.handles`: ``DroneHandle``, ``SchedulerHandle`` ...), which list the methods
they offer as :class:`remote_method` attributes; the runtime builds them from the classes it is handed
(:class:`aerodaas.protocol.actor_classes.ActorClasses`) and never imports them.
"""
from __future__ import annotations

from typing import Any, Callable

__all__ = ["remote_method", "ComponentHandle"]


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
