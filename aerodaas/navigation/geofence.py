"""Geofences: inclusion/exclusion polygons and circles, checked in local ENU metres.

The zone model is the one QGroundControl plans carry (``geoFence`` object, version 2) and PX4/ArduPilot
enforce as mission fence items (``MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION`` 5001 /
``..._EXCLUSION`` 5002, ``MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION`` 5003 / ``..._EXCLUSION`` 5004):

* if any **inclusion** zone exists, a position must lie inside at least one of them (their *union*);
* a position must lie inside **no exclusion** zone;
* an empty configuration allows everything.

The autopilots read several inclusion zones differently, and the vehicle's own fence must accept the same points
as our gate (:func:`autopilot_disagreement`):

* ArduPilot (``libraries/AC_Fence/AC_PolyFence_loader.cpp`` ``breached(loc)``, which both its breach check and its
  refusal of a GUIDED/AUTO destination use, ``AC_Fence::check_destination_within_fence``) takes their
  *intersection* by default and their union when ``FENCE_OPTIONS`` has bit 1 (``AC_Fence::OPTIONS::
  INCLUSION_UNION``, value 2; ArduCopter's default is 0). Observed on ArduCopter SITL (4.7.0-dev) with two
  overlapping inclusion circles: a GUIDED target inside one circle only is silently dropped (the vehicle keeps its
  previous target, no COMMAND_ACK, no text) with ``FENCE_OPTIONS`` 0 and flown with 2. The MAVLink backend sets
  that bit whenever it uploads two or more inclusion zones.
* PX4 (``src/modules/navigator/geofence.cpp`` ``isInsidePolygonOrCircle``: ``checksPass &=`` over every zone) takes
  their *intersection*, with no parameter to change it, and drops a zone that does not hold the home position
  when uploaded (``checkHomeRequirementsForGeofence``). Observed on PX4 SIH (main 02e73e3b6f) with the same two
  circles and ``GF_ACTION`` 2: a DO_REPOSITION into one circle only is acknowledged and ignored ("Reposition is
  outside geofence"). So a fence of two or more inclusion zones is refused for a PX4 vehicle before flight.

Fences are two-dimensional (latitude/longitude); a maximum altitude is a separate vehicle parameter and is
not modelled here. A position exactly on a zone's boundary counts as inside an inclusion zone and outside
an exclusion zone (i.e. the boundary itself is allowed).

:class:`GeofenceConfig` is the pydantic model embedded in ``environment.json`` and in
:class:`aerodaas.missionfile.MissionPlan`. :class:`Geofence` projects it to ENU metres about a home
:class:`~aerodaas.model.types.GeoPoint` (pymap3d via :mod:`aerodaas.model.geo`) and answers point and leg queries with
Shapely (GEOS) geometry; circle tests are exact (distance to centre), not polygonised.

Sources: QGroundControl plan file format (docs ``qgc-dev-guide/file_formats/plan.md``;
``QGCFencePolygon``/``QGCFenceCircle``), MAVLink ``MAV_CMD_NAV_FENCE_*`` definitions.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Sequence

from pydantic import BaseModel, ConfigDict, Field, Strict, field_validator

from aerodaas.model.geo import geodetic_to_enu
from aerodaas.model.types import GeoPoint

if TYPE_CHECKING:
    from shapely.geometry import LineString, Polygon

__all__ = ["GeofencePolygon", "GeofenceCircle", "GeofenceConfig", "Geofence", "autopilot_disagreement"]

#: Leg coverage tolerance in metres: gaps shorter than this between inclusion zones are ignored (float noise).
_COVER_TOL_M = 1e-6


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True, strict=True, allow_inf_nan=False)


def _check_lat_lon(lat: float, lon: float, where: str) -> None:
    if not (isinstance(lat, (int, float)) and math.isfinite(lat) and -90.0 <= lat <= 90.0):
        raise ValueError(f"{where}: latitude must be a finite number within [-90, 90] degrees, got {lat!r}")
    if not (isinstance(lon, (int, float)) and math.isfinite(lon) and -180.0 <= lon <= 180.0):
        raise ValueError(f"{where}: longitude must be a finite number within [-180, 180] degrees, got {lon!r}")


class GeofencePolygon(_Model):
    """A polygonal fence zone: ``points`` are ``(latitude, longitude)`` vertices in WGS-84 degrees (at least 3,
    not repeating the first vertex at the end, as QGroundControl stores them); ``inclusion=True`` means the
    vehicle must stay inside, ``False`` that it must stay out. Must be a simple (non self-intersecting) polygon
    once projected; that is checked when a :class:`Geofence` is built."""

    points: list[Annotated[tuple[float, float], Strict(False)]] = Field(min_length=3, max_length=100_000)
    inclusion: bool = True

    @field_validator("points")
    @classmethod
    def _valid_points(cls, v: list[tuple[float, float]]) -> list[tuple[float, float]]:
        for i, (lat, lon) in enumerate(v):
            _check_lat_lon(lat, lon, f"points[{i}] = ({lat!r}, {lon!r})")
        if len({(float(a), float(b)) for a, b in v}) < 3:
            raise ValueError(f"points: a polygon needs at least 3 distinct vertices, got {v!r}")
        return v


class GeofenceCircle(_Model):
    """A circular fence zone: ``center`` is ``(latitude, longitude)`` in WGS-84 degrees, ``radius`` in metres
    (> 0); ``inclusion=True`` means the vehicle must stay inside, ``False`` that it must stay out."""

    center: Annotated[tuple[float, float], Strict(False)]
    radius: float = Field(gt=0.0, le=1e6)
    inclusion: bool = True

    @field_validator("center")
    @classmethod
    def _valid_center(cls, v: tuple[float, float]) -> tuple[float, float]:
        _check_lat_lon(v[0], v[1], f"center = ({v[0]!r}, {v[1]!r})")
        return v

    @field_validator("radius")
    @classmethod
    def _finite_radius(cls, v: float) -> float:
        if not math.isfinite(v):
            raise ValueError(f"radius must be a finite number of metres, got {v!r}")
        return v


class GeofenceConfig(_Model):
    """All fence zones of a mission or environment (QGroundControl ``geoFence``: ``polygons`` and ``circles``).
    Zones are referred to by their index in ``polygons`` / ``circles`` in every message."""

    polygons: list[GeofencePolygon] = Field(default_factory=list, max_length=1000)
    circles: list[GeofenceCircle] = Field(default_factory=list, max_length=1000)

    @property
    def is_empty(self) -> bool:
        """True when there is no zone at all (everything is allowed)."""
        return not self.polygons and not self.circles

    @property
    def inclusion_count(self) -> int:
        """How many inclusion zones (polygons and circles) there are."""
        return sum(p.inclusion for p in self.polygons) + sum(c.inclusion for c in self.circles)


def autopilot_disagreement(config: GeofenceConfig, autopilot: str) -> str | None:
    """Why ``autopilot``'s own fence (``"ardupilot"`` or ``"px4"``), once the MAVLink backend has uploaded
    ``config`` and set its fence parameters, would accept other points than :class:`Geofence` does; None when both
    accept the same set (see the module docstring for each firmware's rule and its source).

    ArduPilot: None (the backend sets ``FENCE_OPTIONS`` bit 1, the union; a firmware without that parameter is
    refused by the backend when it finds it missing). PX4: a reason for two or more inclusion zones (PX4 takes
    their intersection). The home position must also be allowed by every zone for PX4 to keep it; that holds for
    any fence our gate accepts the home in with at most one inclusion zone (checked where the robot's home is)."""
    n = config.inclusion_count
    if autopilot == "px4" and n > 1:
        return (f"{n} inclusion zones: PX4 requires a position inside every inclusion zone (navigator geofence.cpp "
                f"isInsidePolygonOrCircle), AeroDaaS inside any one of them, so PX4 would refuse or fence off "
                f"targets our gate accepts (a DO_REPOSITION into one zone only is acknowledged and ignored); draw the "
                f"allowed area as one inclusion polygon, or fly on AeroDaaS's gate alone (mavlink.fence.upload false)")
    return None


class _Zone:
    """One projected zone: a Shapely polygon, or an exact circle (centre, radius) in ENU metres."""

    def __init__(self, kind: str, index: int, inclusion: bool, polygon: Polygon | None = None,
                 center: tuple[float, float] | None = None, radius: float = 0.0) -> None:
        self.kind, self.index, self.inclusion = kind, index, inclusion
        self.polygon, self.center, self.radius = polygon, center, radius

    @property
    def label(self) -> str:
        role = "inclusion" if self.inclusion else "exclusion"
        if self.kind == "circle":
            return f"{role} circle {self.index} (radius {self.radius:g} m)"
        return f"{role} polygon {self.index}"

    # -- points -------------------------------------------------------------------------------------------
    def covers(self, x: float, y: float) -> bool:
        """Inside or on the boundary."""
        if self.polygon is not None:
            from shapely.geometry import Point  # lazy: heavy shapely, only with a polygon zone

            return bool(self.polygon.covers(Point(x, y)))
        return math.hypot(x - self.center[0], y - self.center[1]) <= self.radius

    def interior_contains(self, x: float, y: float) -> bool:
        """Strictly inside (the boundary excluded)."""
        if self.polygon is not None:
            from shapely.geometry import Point  # lazy: heavy shapely, only with a polygon zone

            return bool(self.polygon.contains(Point(x, y)))
        return math.hypot(x - self.center[0], y - self.center[1]) < self.radius

    # -- legs ---------------------------------------------------------------------------------------------
    def leg_enters_interior(self, p0: tuple[float, float], p1: tuple[float, float]) -> bool:
        """True if some part of the straight leg p0 -> p1 lies strictly inside the zone."""
        if self.polygon is not None:
            from shapely.geometry import LineString  # lazy: heavy shapely, only with a polygon zone

            # DE-9IM: the interior of the leg meets the interior of the polygon (boundary contact is allowed)
            return bool(LineString([p0, p1]).relate_pattern(self.polygon, "T********"))
        return _segment_point_distance(p0, p1, self.center) < self.radius

    def covered_intervals(self, p0: tuple[float, float], p1: tuple[float, float]) -> list[tuple[float, float]]:
        """Parameter intervals ``[t0, t1]`` (0 = p0, 1 = p1) of the leg that lie inside or on the zone."""
        length = math.hypot(p1[0] - p0[0], p1[1] - p0[1])
        if self.polygon is not None:
            from shapely.geometry import LineString, Point  # lazy: heavy shapely, only with a polygon zone

            line = LineString([p0, p1])
            out = []
            for part in _lines_of(line.intersection(self.polygon)):
                ts = [line.project(Point(c)) / length for c in part.coords]
                out.append((min(ts), max(ts)))
            return out
        # exact circle: |p0 + t d - c|^2 <= r^2
        dx, dy = p1[0] - p0[0], p1[1] - p0[1]
        fx, fy = p0[0] - self.center[0], p0[1] - self.center[1]
        a = dx * dx + dy * dy
        b = 2.0 * (fx * dx + fy * dy)
        c = fx * fx + fy * fy - self.radius * self.radius
        disc = b * b - 4.0 * a * c
        if disc < 0.0:
            return []
        sq = math.sqrt(disc)
        t0, t1 = (-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)
        lo, hi = max(t0, 0.0), min(t1, 1.0)
        return [(lo, hi)] if lo <= hi else []


def _lines_of(geom) -> list[LineString]:
    if geom.is_empty:
        return []
    if geom.geom_type == "LineString":
        return [geom]
    if hasattr(geom, "geoms"):
        out: list[LineString] = []
        for g in geom.geoms:
            out.extend(_lines_of(g))
        return out
    return []  # points: touching only


def _segment_point_distance(p0: tuple[float, float], p1: tuple[float, float], c: tuple[float, float]) -> float:
    dx, dy = p1[0] - p0[0], p1[1] - p0[1]
    a = dx * dx + dy * dy
    t = 0.0 if a == 0.0 else max(0.0, min(1.0, ((c[0] - p0[0]) * dx + (c[1] - p0[1]) * dy) / a))
    return math.hypot(p0[0] + t * dx - c[0], p0[1] + t * dy - c[1])


class Geofence:
    """A :class:`GeofenceConfig` projected to local ENU metres about ``home`` (x east, y north, as every
    AeroDaaS local position), ready for point and leg checks.

    Raises :class:`ValueError` naming the zone if a polygon is not simple once projected (self-intersecting
    or degenerate).
    """

    def __init__(self, config: GeofenceConfig, home: GeoPoint) -> None:
        self.config = config
        self.home = home
        self._zones: list[_Zone] = []
        for i, poly in enumerate(config.polygons):
            from shapely.geometry import Polygon  # lazy: heavy shapely, only with a polygon zone
            from shapely.validation import explain_validity  # lazy: heavy shapely, only with a polygon zone

            pts = [geodetic_to_enu(lat, lon, home.alt, home)[:2] for lat, lon in poly.points]
            shape = Polygon(pts)
            if not shape.is_valid or shape.area <= 0.0:
                raise ValueError(f"polygons[{i}]: not a simple polygon ({explain_validity(shape)}); "
                                 f"points={poly.points!r}")
            self._zones.append(_Zone("polygon", i, poly.inclusion, polygon=shape))
        for i, circ in enumerate(config.circles):
            e, n, _ = geodetic_to_enu(circ.center[0], circ.center[1], home.alt, home)
            self._zones.append(_Zone("circle", i, circ.inclusion, center=(e, n), radius=float(circ.radius)))
        self._inclusions = [z for z in self._zones if z.inclusion]
        self._exclusions = [z for z in self._zones if not z.inclusion]

    @property
    def inclusions(self) -> tuple:
        """The inclusion zones (polygons first, then circles, in config order), in local ENU metres: each has
        ``kind`` (``"polygon"``/``"circle"``), ``index``, ``label``, ``polygon`` (Shapely; None for a circle),
        ``center`` (x, y) and ``radius`` (metres)."""
        return tuple(self._inclusions)

    @property
    def exclusions(self) -> tuple:
        """The exclusion zones, as :attr:`inclusions`."""
        return tuple(self._exclusions)

    @property
    def is_empty(self) -> bool:
        """True when no zone exists (everything allowed)."""
        return not self._zones

    def check_point(self, x: float, y: float) -> str | None:
        """``None`` if the ENU position (metres east ``x``, north ``y`` of home) is allowed, else the reason,
        e.g. ``"outside inclusion polygon 0"`` or ``"inside exclusion circle 1 (radius 20 m)"``."""
        for z in self._exclusions:
            if z.interior_contains(x, y):
                return f"inside {z.label}"
        if self._inclusions and not any(z.covers(x, y) for z in self._inclusions):
            return f"outside {self._inclusion_names()}"
        return None

    def contains(self, x: float, y: float) -> bool:
        """True if the ENU position (metres) is allowed by the fence."""
        return self.check_point(x, y) is None

    def check_segment(self, p0: Sequence[float], p1: Sequence[float]) -> str | None:
        """``None`` if the straight leg ``p0 -> p1`` (ENU metres ``(x, y)``) stays allowed over its whole length,
        else the reason: ``"leg crosses exclusion polygon 2"``, ``"leg leaves inclusion polygon 0 at
        (x, y) m"`` (the first point of the leg outside every inclusion zone), or the end point's reason."""
        a = (float(p0[0]), float(p0[1]))
        b = (float(p1[0]), float(p1[1]))
        length = math.hypot(b[0] - a[0], b[1] - a[1])
        if length <= _COVER_TOL_M:
            return self.check_point(*a)
        for z in self._exclusions:
            if z.leg_enters_interior(a, b):
                return f"leg crosses {z.label}"
        if self._inclusions:
            gap = self._first_uncovered(a, b, length)
            if gap is not None:
                x = a[0] + gap * (b[0] - a[0])
                y = a[1] + gap * (b[1] - a[1])
                return f"leg leaves {self._inclusion_names()} at ({x:.1f}, {y:.1f}) m"
        return None

    def check_path(self, points: Sequence[Sequence[float]]) -> str | None:
        """Check consecutive legs of a path of ENU ``(x, y)`` points; the first violation names the leg index
        (``"leg 2 (point 2 -> 3): leg crosses ..."``) or the single point of a one-point path."""
        pts = list(points)
        if len(pts) == 1:
            return self.check_point(pts[0][0], pts[0][1])
        for i in range(len(pts) - 1):
            reason = self.check_segment(pts[i], pts[i + 1])
            if reason:
                return f"leg {i} (point {i} -> {i + 1}): {reason}"
        return None

    # -- helpers ------------------------------------------------------------------------------------------
    def _inclusion_names(self) -> str:
        if len(self._inclusions) == 1:
            return self._inclusions[0].label
        return "every inclusion zone (" + ", ".join(z.label for z in self._inclusions) + ")"

    def _first_uncovered(self, a: tuple[float, float], b: tuple[float, float], length: float) -> float | None:
        """Smallest leg parameter t in [0, 1] not covered by any inclusion zone, or None if fully covered."""
        intervals = sorted(iv for z in self._inclusions for iv in z.covered_intervals(a, b))
        tol = _COVER_TOL_M / length
        reach = 0.0
        for lo, hi in intervals:
            if lo > reach + tol:
                break
            reach = max(reach, hi)
        return None if reach >= 1.0 - tol else reach
