"""Plug-ins: one registry (:mod:`aerodaas.plugins.registry`) for the five extension points — vehicle backends,
sensor types, analytics, trajectory schedulers and analytics schedulers — and the base class of a sensor type
(:class:`aerodaas.plugins.sensor.SensorPlugin`). ``docs/extending.md`` walks through an example package."""
from __future__ import annotations

from aerodaas.plugins.registry import (ENTRY_POINT_GROUPS, KINDS, PluginEntry, UnknownPlugin, describe_all, entries,
                                       get, plugin, register, resolve)
from aerodaas.plugins.sensor import SensorPlugin, SensorPluginConfig

__all__ = ["ENTRY_POINT_GROUPS", "KINDS", "PluginEntry", "UnknownPlugin", "describe_all", "entries", "get", "plugin",
           "register", "resolve", "SensorPlugin", "SensorPluginConfig", "register_sensor", "register_backend",
           "register_analytics", "register_trajectory_scheduler", "get_plugin"]


def register_sensor(cls: type) -> type:
    """Class decorator: register a :class:`SensorPlugin` subclass under its ``name`` (the sensor ``type``)."""
    return register(cls, "sensor")


def register_backend(cls: type) -> type:
    """Class decorator: register a :class:`aerodaas.backends.base.VehicleBackend` subclass under its ``kind``."""
    return register(cls, "backend")


def register_analytics(cls: type) -> type:
    """Class decorator: register an :class:`aerodaas.analytics.core.Analytics` subclass under its ``name``."""
    return register(cls, "analytics")


def register_trajectory_scheduler(cls: type) -> type:
    """Class decorator: register a :class:`aerodaas.schedulers.TrajectoryScheduler` subclass under its class name
    (or ``plugin_name``)."""
    return register(cls, "trajectory_scheduler", getattr(cls, "plugin_name", None) or cls.__name__)


def get_plugin(kind: str, name: str) -> type:
    """The plug-in class ``name`` of ``kind`` (see :func:`aerodaas.plugins.registry.get`)."""
    return get(kind, name)
