"""ComplexItem expansion: the MAVLink items QGroundControl uploads for a ``.plan`` ComplexItem
(:func:`expand_items`). Survey and corridor scans carry their items; a structure scan is regenerated with
QGroundControl's ``StructureScanComplexItem::appendMissionItems`` algorithm (the polygon offset of
``QGCMapPolygon::offset``, in a WGS-84 local tangent plane). See the package docstring for the rules."""
from __future__ import annotations

import math
from typing import Any, Protocol

from aerodaas.model.geo import enu_to_geodetic, geodetic_to_enu
from aerodaas.model.types import GeoPoint
from aerodaas.missionfile._common import _fail, _is_number
from aerodaas.missionfile.commands import (MAV_CMD_DO_SET_CAM_TRIGG_DIST, MAV_CMD_DO_SET_ROI_NONE, MAV_CMD_DO_SET_ROI_WPNEXT_OFFSET,
                       MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT, MAV_FRAME_MISSION)
from aerodaas.missionfile.items import MissionItem, _parse_simple_item


class PlanItems(Protocol):
    """What :func:`expand_items` reads of a plan: a :class:`~aerodaas.missionfile.plans.MissionPlan` is one (it
    calls :func:`expand_items`, so this module does not import it)."""

    #: the mission items in order
    items: list[MissionItem]
    #: the file the plan was read from (error messages), None for a plan built in code
    source: str | None


def expand_items(plan: PlanItems) -> list[MissionItem]:
    """See :meth:`aerodaas.missionfile.plans.MissionPlan.expanded_items`."""
    src = plan.source or "<plan>"
    out: list[MissionItem] = []
    for k, item in enumerate(plan.items):
        if item.raw is None:
            out.append(item)
            continue
        ctype = item.complex_type
        where = f"mission.items[{k}] (ComplexItem {ctype!r}, item {item.seq})"
        tsci = item.raw.get("TransectStyleComplexItem")
        if ctype in ("survey", "CorridorScan"):
            if not isinstance(tsci, dict) or not isinstance(tsci.get("Items"), list) or not tsci["Items"]:
                raise _fail(src, where, "has no TransectStyleComplexItem.Items to expand; open and re-save it in "
                                        "QGroundControl, which stores the generated items")
            for j, sub in enumerate(tsci["Items"]):
                sub_item = _parse_simple_item(src, f"{where} TransectStyleComplexItem.Items[{j}]", sub, item.seq + j)
                out.append(sub_item.model_copy(update={"seq": item.seq + j}))
        elif ctype == "StructureScan":
            out.extend(_expand_structure_scan(src, where, item.raw, item.seq))
        else:
            raise _fail(src, where, "AeroDaaS cannot expand this ComplexItem into MAVLink items (supported: survey, "
                                    "CorridorScan, StructureScan); it is kept verbatim in .plan exports only")
    return out


class _QLine:
    """The parts of Qt's ``QLineF`` that ``QGCMapPolygon::offset`` uses (angles counter-clockwise in Qt's
    y-down convention, i.e. ``atan2(-dy, dx)``)."""

    def __init__(self, x1: float, y1: float, x2: float, y2: float) -> None:
        self.x1, self.y1, self.x2, self.y2 = x1, y1, x2, y2

    def length(self) -> float:
        return math.hypot(self.x2 - self.x1, self.y2 - self.y1)

    def angle(self) -> float:
        theta = math.degrees(math.atan2(-(self.y2 - self.y1), self.x2 - self.x1))
        theta = theta + 360.0 if theta < 0 else theta
        return 0.0 if abs(theta - 360.0) <= 1e-12 * 360.0 else theta

    def set_length(self, length: float) -> None:
        old = self.length()
        if old > 0:
            self.x2 = self.x1 + length * ((self.x2 - self.x1) / old)
            self.y2 = self.y1 + length * ((self.y2 - self.y1) / old)

    def set_angle(self, angle: float) -> None:
        r = math.radians(angle)
        length = self.length()
        self.x2 = self.x1 + math.cos(r) * length
        self.y2 = self.y1 - math.sin(r) * length

    def intersects(self, other: "_QLine") -> tuple[float, float] | None:
        ax, ay = self.x2 - self.x1, self.y2 - self.y1
        bx, by = other.x1 - other.x2, other.y1 - other.y2
        cx, cy = self.x1 - other.x1, self.y1 - other.y1
        den = ay * bx - ax * by
        if den == 0 or not math.isfinite(den):
            return None
        na = (by * cx - bx * cy) / den
        return (self.x1 + ax * na, self.y1 + ay * na)


def _offset_polygon(vertices: list[tuple[float, float]], distance: float) -> list[tuple[float, float]] | None:
    """``QGCMapPolygon::offset``: shift every edge by ``distance`` metres to its left (outward for the clockwise
    polygons QGroundControl draws) in a WGS-84 tangent plane at vertex 0, intersect consecutive shifted edges.
    Returns ``None`` where QGroundControl's intersection fails (parallel consecutive edges)."""
    lat0, lon0 = vertices[0]
    origin = GeoPoint(lat=lat0, lon=lon0, alt=0.0)
    pts = [(0.0, 0.0)] + [geodetic_to_enu(lat, lon, 0.0, origin)[:2] for lat, lon in vertices[1:]]
    edges: list[_QLine] = []
    n = len(pts)
    for i in range(n):
        p, q = pts[i], pts[(i + 1) % n]
        worker = _QLine(p[0], p[1], q[0], q[1])
        worker.set_length(distance)
        worker.set_angle(worker.angle() - 90.0)
        p1 = (worker.x2, worker.y2)
        worker = _QLine(q[0], q[1], p[0], p[1])
        worker.set_length(distance)
        worker.set_angle(worker.angle() + 90.0)
        edges.append(_QLine(p1[0], p1[1], worker.x2, worker.y2))
    out = []
    for i in range(n):
        hit = edges[i - 1].intersects(edges[i])
        if hit is None:
            return None
        g = enu_to_geodetic(hit[0], hit[1], 0.0, origin)
        out.append((g.lat, g.lon))
    return out


def _expand_structure_scan(src: str, where: str, raw: dict[str, Any], seq0: int) -> list[MissionItem]:
    """QGroundControl ``StructureScanComplexItem`` (version 3) -> MAVLink items, as ``appendMissionItems`` builds
    them (entry vertex 0, which QGroundControl does not save and resets to 0 on load)."""
    if raw.get("version") != 3:
        raise _fail(src, where, f"only StructureScan version 3 can be expanded, got version {raw.get('version')!r}")
    for key in ("ScanBottomAlt", "StructureHeight", "Layers", "EntranceAltitude", "GimbalPitch"):
        if not _is_number(raw.get(key)):
            raise _fail(src, where, f"{key} must be a number, got {raw.get(key)!r}")
    if not isinstance(raw.get("StartFromTop"), bool):
        raise _fail(src, where, f"StartFromTop must be true or false, got {raw.get('StartFromTop')!r}")
    cam = raw.get("CameraCalc")
    if not isinstance(cam, dict):
        raise _fail(src, where, f"CameraCalc must be an object, got {cam!r:.80}")
    for key in ("AdjustedFootprintFrontal", "AdjustedFootprintSide", "DistanceToSurface"):
        if not _is_number(cam.get(key)):
            raise _fail(src, where, f"CameraCalc.{key} must be a number, got {cam.get(key)!r}")
    poly = raw.get("polygon")
    if not isinstance(poly, list) or len(poly) < 3 or not all(
            isinstance(p, list) and len(p) >= 2 and _is_number(p[0]) and _is_number(p[1]) for p in poly):
        raise _fail(src, where, f"polygon must hold at least 3 [latitude, longitude] vertices, got {poly!r:.120}")
    for j, p in enumerate(poly):
        if not (-90 <= p[0] <= 90 and -180 <= p[1] <= 180):
            raise _fail(src, where, f"polygon[{j}] = {p!r} is not a valid latitude/longitude")

    frontal = float(cam["AdjustedFootprintFrontal"])
    side = float(cam["AdjustedFootprintSide"])
    if frontal <= 0:
        raise _fail(src, where, f"CameraCalc.AdjustedFootprintFrontal must be > 0 m, got {frontal!r}")
    height, bottom = float(raw["StructureHeight"]), float(raw["ScanBottomAlt"])
    layers = int(raw["Layers"])
    expected_layers = max(math.ceil(max(height - bottom, 0.0) / frontal), 1)  # StructureScan::_recalcLayerInfo
    if layers != raw["Layers"] or layers != expected_layers:
        raise _fail(src, where, f"Layers = {raw['Layers']!r} disagrees with QGroundControl's layer count "
                                f"ceil((StructureHeight {height:g} - ScanBottomAlt {bottom:g}) / "
                                f"AdjustedFootprintFrontal {frontal:g}) = {expected_layers}; QGroundControl would "
                                "recompute it on load, so the flown layers are ambiguous")
    if layers > 10000:
        raise _fail(src, where, f"Layers = {layers} is not a plausible structure scan")
    flight = _offset_polygon([(float(p[0]), float(p[1])) for p in poly], float(cam["DistanceToSurface"]))
    if flight is None:
        raise _fail(src, where, "the structure polygon has parallel consecutive edges; QGroundControl cannot "
                                "offset it (it would fly the structure outline itself)")

    start_from_top = raw["StartFromTop"]
    entrance_alt = float(raw["EntranceAltitude"])
    nan = None
    items: list[MissionItem] = []

    def add(command: int, frame: int, params: list[float | None]) -> None:
        items.append(MissionItem(seq=seq0 + len(items), command=command, frame=frame, params=params))

    entry = flight[0]
    add(MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT, [0, 0, 0, nan, entry[0], entry[1], entrance_alt])
    add(MAV_CMD_DO_SET_ROI_WPNEXT_OFFSET, MAV_FRAME_MISSION, [0, 0, 0, 0, float(raw["GimbalPitch"]), 0, 90])
    half = frontal / 2.0
    layer_alt = (height - half) if start_from_top else (bottom + half)
    for _layer in range(layers):
        for k in range(len(flight) + 1):
            v = flight[k % len(flight)]
            add(MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT, [0, 0, 0, nan, v[0], v[1], layer_alt])
            if k == 0:
                add(MAV_CMD_DO_SET_CAM_TRIGG_DIST, MAV_FRAME_MISSION, [side, 0, 1, 0, 0, 0, 0])
        add(MAV_CMD_DO_SET_CAM_TRIGG_DIST, MAV_FRAME_MISSION, [0, 0, 0, 0, 0, 0, 0])
        layer_alt += -2 * half if start_from_top else 2 * half
    add(MAV_CMD_DO_SET_ROI_NONE, MAV_FRAME_MISSION, [0, 0, 0, 0, 0, 0, 0])
    add(MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL_RELATIVE_ALT, [0, 0, 0, nan, entry[0], entry[1], entrance_alt])
    return items
