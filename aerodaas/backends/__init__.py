"""Vehicle backends: the embedded simulator, MAVLink autopilots (ArduPilot, PX4), the DJI Tello, and replay of
recorded flights. :func:`make_backend` builds the one a robot's ``backend`` names in ``environment.json``."""
from __future__ import annotations

from aerodaas.backends.base import BackendError, CommandRefused, LinkLost, NotNavigable, VehicleBackend

__all__ = ["VehicleBackend", "BackendError", "CommandRefused", "LinkLost", "NotNavigable", "make_backend",
           "NAVIGABLE"]

#: whether each backend can fly navigation (the replay of a log only reports); known without importing drivers
NAVIGABLE = {"sim": True, "mavlink": True, "tello": True, "replay": False}


def make_backend(cfg) -> VehicleBackend:
    """The backend for ``cfg`` (an :class:`aerodaas.config.RobotConfig`). Imports the driver lazily, so a robot on
    the simulator never imports pymavlink. Raises ValueError for an unknown ``backend``."""
    if cfg.backend == "sim":
        from aerodaas.backends.sim import SimBackend

        return SimBackend(cfg)
    if cfg.backend == "mavlink":
        from aerodaas.backends.mavlink import MavlinkBackend

        return MavlinkBackend(cfg)
    if cfg.backend == "tello":
        from aerodaas.backends.tello import TelloBackend

        return TelloBackend(cfg)
    if cfg.backend == "replay":
        from aerodaas.backends.replay import ReplayBackend

        return ReplayBackend(cfg)
    raise ValueError(f"robots[{cfg.id!r}].backend: unknown backend {cfg.backend!r}; "
                     f"choose from ['sim', 'mavlink', 'tello', 'replay']")
