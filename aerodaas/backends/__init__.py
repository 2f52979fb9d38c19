"""Vehicle backends: the embedded simulator, MAVLink autopilots (ArduPilot, PX4), the DJI Tello, and replay of
recorded flights. :func:`make_backend` builds the one a robot's ``backend`` names in ``environment.json``."""
from __future__ import annotations

from aerodaas.backends.base import (Actions, BackendError, CommandRefused, Guidance, LinkLost, NotNavigable,
                                   VehicleBackend, VehicleState)
from aerodaas.plugins import registry

__all__ = ["VehicleBackend", "VehicleState", "BackendError", "CommandRefused", "LinkLost", "NotNavigable",
           "make_backend", "backend_class", "is_navigable", "backend_clock"]


def backend_class(name: str) -> type[VehicleBackend]:
    """The backend class ``name`` (a ``robots[].backend`` value) names: a built-in (imported lazily, so a robot on
    the simulator never imports pymavlink), a plug-in registered with a decorator or installed under the entry
    point group ``aerodaas.backends``, or ``"module.path:ClassName"`` (:mod:`aerodaas.plugins.registry`). Raises
    ValueError (UnknownPlugin) listing the available backends and where each came from."""
    return registry.get("backend", name)


def is_navigable(name: str) -> bool:
    """Whether backend ``name`` can fly navigation (its class's ``navigable``; the replay of a log only reports)."""
    return bool(getattr(backend_class(name), "navigable", True))


def backend_clock(name: str) -> str:
    """``"sim"`` for a backend that moves only when stepped (lock-step is possible), else ``"vehicle"`` (its
    class's ``clock``)."""
    return str(getattr(backend_class(name), "clock", "vehicle"))


def make_backend(cfg) -> VehicleBackend:
    """The backend for ``cfg`` (an :class:`aerodaas.config.RobotConfig`): ``backend_class(cfg.backend)(cfg)``.
    Raises ValueError for an unknown ``backend``; TypeError naming the backend when its ``__init__`` set no command
    group ``actions`` (:class:`~aerodaas.backends.base.Actions`) or ``guidance``
    (:class:`~aerodaas.backends.base.Guidance`), or one without every command of its group."""
    backend = backend_class(cfg.backend)(cfg)
    for name, group in (("actions", Actions), ("guidance", Guidance)):
        if not isinstance(getattr(backend, name, None), group):
            missing = [m for m in group.__dict__ if not m.startswith("_") and callable(getattr(group, m))
                       and not callable(getattr(getattr(backend, name, None), m, None))]
            raise TypeError(f"backend {cfg.backend!r} ({type(backend).__name__}): its __init__ must set "
                            f"self.{name} to an object with {', '.join(m + '()' for m in missing)} (VehicleBackend {name})")
    return backend
