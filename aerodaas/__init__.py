"""AeroDaaS: a Drones-as-a-Service programming framework on Ray.

The public API (paper Table 2, Python style) is importable from here::

    from aerodaas import *

Its names are resolved on first use (PEP 562 module ``__getattr__``; ``from aerodaas import *`` and
``aerodaas.Environment`` resolve them as before): importing a sub-module such as ``aerodaas.cli`` or an actor's
module runs only that module's own imports, not the whole API (numpy, pydantic models, the analytics), which a
Ray actor that never builds an application (the recorder) and every command that loads none (``aerodaas info``,
``--help``) paid at each start. An unknown name raises AttributeError naming it.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

#: the module that defines each public name (a name's own, under an alias for the paper's interface names)
_ORIGIN: dict[str, tuple[str, str]] = {
    **{n: ("aerodaas.analytics.core", n) for n in ("Analytics", "FollowAnalytics", "IAnalyse", "INavigableAnalyse",
                                                  "MonitoringAnalytics", "NavigableAnalytics", "ObjectDetector")},
    **{n: ("aerodaas.app.api", n) for n in ("ComputeResource", "Environment", "Robot", "Sensor")},
    "IEnvironment": ("aerodaas.app.api", "Environment"), "IRobot": ("aerodaas.app.api", "Robot"),
    "ISensor": ("aerodaas.app.api", "Sensor"), "ICompute": ("aerodaas.app.api", "ComputeResource"),
    "ConfigError": ("aerodaas.config", "ConfigError"),
    **{n: ("aerodaas.model.data", n) for n in ("AeroData", "AeroListData", "AeroStreamData", "IAeroData")},
    **{n: ("aerodaas.navigation.fsm", n) for n in ("IllegalTransition", "MissionState")},
    **{n: ("aerodaas.model.types", n) for n in ("ActionCommand", "AeroNavigation", "Detection", "NavigationType",
                                                "Odometry", "PriorityQueue", "SchedulingType", "VelocityCommand",
                                                "Waypoint")},
    "AeroNav": ("aerodaas.model.types", "AeroNavigation"),
    **{n: ("aerodaas.schedulers", n) for n in ("NearestNeighborScheduler", "TrajectoryScheduler",
                                               "TwoOptScheduler")},
    "INavigate": ("aerodaas.schedulers", "TrajectoryScheduler"),
    "TrackAnalytics": ("aerodaas.analytics.track", "TrackAnalytics"),
    "ByteTrackConfig": ("aerodaas.perception.tracking", "ByteTrackConfig"),
    "Tiling": ("aerodaas.perception.tiling", "Tiling"),
    "MovingTarget": ("aerodaas.analytics.motion", "MovingTarget"),
}

__all__ = [
    "Environment", "Robot", "Sensor", "ComputeResource", "IEnvironment", "IRobot", "ISensor", "ICompute",
    "Analytics", "IAnalyse", "NavigableAnalytics", "INavigableAnalyse", "ObjectDetector", "FollowAnalytics",
    "MonitoringAnalytics", "AeroData", "IAeroData", "AeroListData", "AeroStreamData", "AeroNavigation", "AeroNav",
    "NavigationType", "SchedulingType", "PriorityQueue", "Waypoint", "VelocityCommand", "Odometry", "Detection",
    "MissionState", "IllegalTransition", "ConfigError", "TrajectoryScheduler", "NearestNeighborScheduler",
    "INavigate", "TwoOptScheduler", "ActionCommand", "TrackAnalytics", "ByteTrackConfig",
    "MovingTarget", "Tiling",
]


def __getattr__(name: str) -> Any:
    """The public name ``name``, imported from its module on first use and kept in this module's namespace.
    Raises AttributeError for a name that is not public (as a plain module attribute lookup does)."""
    origin = _ORIGIN.get(name)
    if origin is None:
        raise AttributeError(f"module 'aerodaas' has no attribute {name!r}")
    value = getattr(importlib.import_module(origin[0]), origin[1])
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The module's names, the public API's included before any was used (for ``dir()`` and completion)."""
    return sorted({*globals(), *__all__})


if TYPE_CHECKING:  # what type checkers and IDEs read: the eager imports the lazy table mirrors
    from aerodaas.analytics.core import (Analytics, FollowAnalytics, IAnalyse, INavigableAnalyse,  # noqa: F401
                                         MonitoringAnalytics, NavigableAnalytics, ObjectDetector)
    from aerodaas.analytics.motion import MovingTarget  # noqa: F401
    from aerodaas.analytics.track import TrackAnalytics  # noqa: F401
    from aerodaas.app.api import ComputeResource, Environment, Robot, Sensor  # noqa: F401
    from aerodaas.config import ConfigError  # noqa: F401
    from aerodaas.model.data import AeroData, AeroListData, AeroStreamData, IAeroData  # noqa: F401
    from aerodaas.model.types import (ActionCommand, AeroNavigation, Detection, NavigationType,  # noqa: F401
                                      Odometry, PriorityQueue, SchedulingType, VelocityCommand, Waypoint)
    from aerodaas.navigation.fsm import IllegalTransition, MissionState  # noqa: F401
    from aerodaas.perception.tiling import Tiling  # noqa: F401
    from aerodaas.perception.tracking import ByteTrackConfig  # noqa: F401
    from aerodaas.schedulers import NearestNeighborScheduler, TrajectoryScheduler, TwoOptScheduler  # noqa: F401

    IEnvironment, IRobot, ISensor, ICompute = Environment, Robot, Sensor, ComputeResource
    AeroNav = AeroNavigation
    INavigate = TrajectoryScheduler
