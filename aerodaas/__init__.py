"""AeroDaaS: a Drones-as-a-Service programming framework on Ray.

The public API (paper Table 2, Python style) is importable from here::

    from aerodaas import *
"""
__version__ = "0.1.0"

from .analytics import (Analytics, FollowAnalytics, IAnalyse, INavigableAnalyse, MonitoringAnalytics,
                        NavigableAnalytics, ObjectDetector)
from .api import ComputeResource, Environment, Robot, Sensor
from .config import ConfigError
from .data import AeroData, AeroListData, AeroStreamData, IAeroData
from .fsm import IllegalTransition, MissionState
from .models import (ActionCommand, AeroNavigation, Detection, NavigationType, Odometry, PriorityQueue,
                     SchedulingType, VelocityCommand, Waypoint)
from .schedulers import NearestNeighborScheduler, TrajectoryScheduler, TwoOptScheduler

IEnvironment, IRobot, ISensor, ICompute = Environment, Robot, Sensor, ComputeResource
AeroNav = AeroNavigation
INavigate = TrajectoryScheduler

__all__ = [
    "Environment", "Robot", "Sensor", "ComputeResource", "IEnvironment", "IRobot", "ISensor", "ICompute",
    "Analytics", "IAnalyse", "NavigableAnalytics", "INavigableAnalyse", "ObjectDetector", "FollowAnalytics",
    "MonitoringAnalytics", "AeroData", "IAeroData", "AeroListData", "AeroStreamData", "AeroNavigation", "AeroNav",
    "NavigationType", "SchedulingType", "PriorityQueue", "Waypoint", "VelocityCommand", "Odometry", "Detection",
    "MissionState", "IllegalTransition", "ConfigError", "TrajectoryScheduler", "NearestNeighborScheduler",
    "INavigate", "TwoOptScheduler", "ActionCommand",
]
