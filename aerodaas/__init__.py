"""AeroDaaS: a Drones-as-a-Service programming framework on Ray.

The public API (paper Table 2, Python style) is importable from here::

    from aerodaas import *
"""
__version__ = "0.1.0"

from aerodaas.analytics.core import (Analytics, FollowAnalytics, IAnalyse, INavigableAnalyse, MonitoringAnalytics,
                        NavigableAnalytics, ObjectDetector)
from aerodaas.app.api import ComputeResource, Environment, Robot, Sensor
from aerodaas.config import ConfigError
from aerodaas.model.data import AeroData, AeroListData, AeroStreamData, IAeroData
from aerodaas.navigation.fsm import IllegalTransition, MissionState
from aerodaas.model.types import (ActionCommand, AeroNavigation, Detection, NavigationType, Odometry, PriorityQueue,
                     SchedulingType, VelocityCommand, Waypoint)
from aerodaas.schedulers import NearestNeighborScheduler, TrajectoryScheduler, TwoOptScheduler
from aerodaas.analytics.track import TrackAnalytics
from aerodaas.perception.tracking import ByteTrackConfig
from aerodaas.analytics.motion import MovingTarget

IEnvironment, IRobot, ISensor, ICompute = Environment, Robot, Sensor, ComputeResource
AeroNav = AeroNavigation
INavigate = TrajectoryScheduler

__all__ = [
    "Environment", "Robot", "Sensor", "ComputeResource", "IEnvironment", "IRobot", "ISensor", "ICompute",
    "Analytics", "IAnalyse", "NavigableAnalytics", "INavigableAnalyse", "ObjectDetector", "FollowAnalytics",
    "MonitoringAnalytics", "AeroData", "IAeroData", "AeroListData", "AeroStreamData", "AeroNavigation", "AeroNav",
    "NavigationType", "SchedulingType", "PriorityQueue", "Waypoint", "VelocityCommand", "Odometry", "Detection",
    "MissionState", "IllegalTransition", "ConfigError", "TrajectoryScheduler", "NearestNeighborScheduler",
    "INavigate", "TwoOptScheduler", "ActionCommand", "TrackAnalytics", "ByteTrackConfig",
    "MovingTarget",
]
