"""NearestNeighborScheduler (the paper's plug-in, §8.3): greedy nearest-neighbour tour over the waypoints."""
from __future__ import annotations

import math
from typing import Sequence

from aerodaas.model.types import Waypoint

from aerodaas.schedulers.base import TrajectoryScheduler


class NearestNeighborScheduler(TrajectoryScheduler):
    """Orders an UNORDERED waypoint list greedily: from ``start``, always fly to the closest unvisited waypoint
    (3-D Euclidean distance in metres; ties keep the given order). O(n²)."""

    name = "nearest_neighbor"

    def order(self, waypoints: list[Waypoint], start: Sequence[float]) -> list[Waypoint]:
        left = list(waypoints)
        out: list[Waypoint] = []
        p = tuple(start)
        while left:
            i = min(range(len(left)), key=lambda j: (math.dist(p, (left[j].x, left[j].y, left[j].z)), j))
            w = left.pop(i)
            out.append(w)
            p = (w.x, w.y, w.z)
        return out
