"""Analytics (the paper's IAnalyse / INavigableAnalyse) and the built-in ones, in one place for applications:
the base classes (:mod:`aerodaas.analytics.base`), an ONNX object detector (:mod:`aerodaas.analytics.detector`), a
PID "follow" navigable analytics (:mod:`aerodaas.analytics.follow`) and odometry monitoring
(:mod:`aerodaas.analytics.monitoring`); the output contract is :mod:`aerodaas.analytics.contract`.

An analytics is a plain Python object built in the application; ``deploy(compute)`` picks its tier and
``analyse(stream)`` wires it into the dataflow. At ``start_mission()`` the runtime ships it to a Ray
actor on that tier, calls :meth:`Analytics.setup` there once (load models), then :meth:`Analytics.process`
for every delivered item (or :meth:`Analytics.process_batch` for several at once). Subclass and override
``setup``/``process`` to write your own (docs/extending.md).
"""
from __future__ import annotations

from aerodaas.analytics.base import Analytics, IAnalyse, INavigableAnalyse, NavigableAnalytics, source_robot
from aerodaas.analytics.detector import ObjectDetector
from aerodaas.analytics.follow import FollowAnalytics, FollowTrack
from aerodaas.analytics.monitoring import MonitoringAnalytics

__all__ = ["Analytics", "IAnalyse", "INavigableAnalyse", "NavigableAnalytics", "ObjectDetector",
           "FollowAnalytics", "FollowTrack", "MonitoringAnalytics", "source_robot"]
