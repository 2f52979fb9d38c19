"""A shortest path around the geofence's exclusion zones, for return-to-launch and every failsafe.

The planner is a visibility graph (Lozano-Pérez & Wesley, "An algorithm for planning collision-free paths among
polyhedral obstacles", CACM 22(10), 1979): every exclusion zone is grown by a ``clearance`` (metres: the stopping
distance at the return speed plus a margin, so the gate's stopping envelope stays clear too) and approximated by a
polygon that *contains* the grown zone (a circle of radius R becomes a regular polygon with circumradius
``R / cos(pi / n)``); the nodes are the start, the goal and the vertices of the grown zones; an edge is a straight leg
that enters no grown zone's interior and that :meth:`aerodaas.navigation.geofence.Geofence.check_segment` allows (inclusion
zones included); Dijkstra's algorithm gives the shortest path. Geometry with Shapely. ``None`` when no safe path
exists: the caller then lands in place.
"""
from __future__ import annotations

import heapq
import math
from typing import TYPE_CHECKING, Sequence

from aerodaas.navigation.geofence import Geofence

if TYPE_CHECKING:
    from shapely.geometry import Polygon

__all__ = ["grown_exclusions", "plan_path"]

#: vertices of the polygon that approximates a grown exclusion circle
CIRCLE_VERTICES = 16


def grown_exclusions(fence: Geofence, clearance: float) -> list[Polygon]:
    """Each exclusion zone of ``fence`` grown by ``clearance`` metres, as a Shapely polygon (ENU metres) that contains
    the grown zone (circles: a circumscribed regular polygon of :data:`CIRCLE_VERTICES` vertices)."""
    from shapely.geometry import Polygon  # lazy: heavy shapely, only when a path is planned

    out = []
    for z in fence.exclusions:
        if z.polygon is not None:
            g = z.polygon.buffer(clearance, join_style="mitre", mitre_limit=2.0) if clearance > 0 else z.polygon
            out.append(g.simplify(0.0))
        else:
            n = CIRCLE_VERTICES
            r = (z.radius + clearance) / math.cos(math.pi / n)
            cx, cy = z.center
            out.append(Polygon([(cx + r * math.cos(2 * math.pi * k / n), cy + r * math.sin(2 * math.pi * k / n))
                                for k in range(n)]))
    return out


def _exterior_points(poly) -> list[tuple[float, float]]:
    geoms = getattr(poly, "geoms", [poly])
    return [tuple(c) for g in geoms for c in list(g.exterior.coords)[:-1]]


def plan_path(fence: Geofence, start: Sequence[float], goal: Sequence[float], clearance: float = 1.0,
              max_nodes: int = 2000) -> list[tuple[float, float]] | None:
    """The shortest path ``[start, ..., goal]`` of ENU ``(x, y)`` points (metres) whose every leg stays ``clearance``
    metres clear of every exclusion zone and inside the inclusion zones, or ``None`` when there is none (or the goal
    itself is forbidden). A start or goal already within the clearance of a zone may leave or enter that grown zone
    (only the zone itself is forbidden there). Raises ``ValueError`` if ``clearance`` is negative or not finite.
    Cost: O(N² · Z) leg checks for N vertices (at most ``max_nodes``) and Z zones."""
    if not (math.isfinite(clearance) and clearance >= 0):
        raise ValueError(f"clearance must be a finite number of metres >= 0, got {clearance!r}")
    from shapely.geometry import LineString, Point  # lazy: heavy shapely, only when a path is planned

    s = (float(start[0]), float(start[1]))
    g = (float(goal[0]), float(goal[1]))
    if fence.check_point(*g) is not None:
        return None
    grown = grown_exclusions(fence, clearance)
    nodes = [s, g]
    for poly in grown:
        for v in _exterior_points(poly):
            if fence.check_point(*v) is None and not any(o.contains(Point(v)) for o in grown):
                nodes.append(v)
    nodes = nodes[:max_nodes]
    around = [[i for i, o in enumerate(grown) if o.intersects(Point(p))] for p in (s, g)]

    def free(a: int, b: int) -> bool:
        pa, pb = nodes[a], nodes[b]
        if math.dist(pa, pb) < 1e-9:
            return True
        if fence.check_segment(pa, pb) is not None:
            return False
        skip = set()
        for end, idx in ((0, a), (1, b)):
            if idx < 2:
                skip.update(around[idx])
        line = LineString([pa, pb])
        return not any(k not in skip and line.relate_pattern(o, "T********") for k, o in enumerate(grown))

    # Dijkstra over the (lazily built) visibility graph
    dist = {0: 0.0}
    prev: dict[int, int] = {}
    heap = [(0.0, 0)]
    done = set()
    while heap:
        d, u = heapq.heappop(heap)
        if u in done:
            continue
        done.add(u)
        if u == 1:
            break
        for w in range(len(nodes)):
            if w in done:
                continue
            nd = d + math.dist(nodes[u], nodes[w])
            if nd < dist.get(w, math.inf) and free(u, w):
                dist[w] = nd
                prev[w] = u
                heapq.heappush(heap, (nd, w))
    if 1 not in done:
        return None
    path, k = [g], 1
    while k != 0:
        k = prev[k]
        path.append(nodes[k])
    return path[::-1]
