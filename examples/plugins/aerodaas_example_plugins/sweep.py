"""Trajectory scheduler ``eastward_sweep``: an UNORDERED survey flown from west to east.

A trajectory scheduler orders the waypoints of an UNORDERED navigation (AeroDaaS asks it again whenever the queue
changes, from the drone's position then). This one ignores the position: it visits the waypoints in increasing
east coordinate (ENU ``x`` of a relative waypoint, the longitude ``y`` of an absolute one), ties broken by north,
so that a survey crosses a gas plume once, in one direction, downwind of a westerly wind.
"""
from __future__ import annotations

from typing import Sequence

from aerodaas import TrajectoryScheduler, Waypoint


class EastwardSweep(TrajectoryScheduler):
    """West to east, whatever the start (see the module). O(n log n)."""

    name = "eastward_sweep"

    def order(self, waypoints: list[Waypoint], start: Sequence[float]) -> list[Waypoint]:
        def east_north(w: Waypoint) -> tuple[float, float]:
            return (w.y, w.x) if w.waypoint_type == "absolute" else (w.x, w.y)

        return sorted(waypoints, key=east_north)
