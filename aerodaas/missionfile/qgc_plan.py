"""QGroundControl ``.plan`` files (JSON; ``fileType`` "Plan" version 1, mission version 2, geoFence and
rallyPoints version 2): :func:`load_plan`, :func:`save_plan` and :func:`plan_to_json`. SimpleItems become
:class:`~aerodaas.missionfile.items.MissionItem` rows, ComplexItems are kept verbatim. Sources: QGroundControl's
plan file format (``docs/en/qgc-dev-guide/file_formats/plan.md``) and its loader/saver (``MissionController``,
``GeoFenceController``, ``QGCFencePolygon``, ``QGCFenceCircle``)."""
from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from aerodaas.navigation.geofence import GeofenceCircle, GeofenceConfig, GeofencePolygon
from aerodaas.model.types import GeoPoint
from aerodaas.missionfile._common import MissionFileError, _fail, _first_error, _is_number, _read_text
from aerodaas.missionfile.commands import COMPLEX_ITEM_COMMAND, MAV_FRAME_MISSION
from aerodaas.missionfile.items import MissionItem, _parse_simple_item
from aerodaas.missionfile.plans import MissionPlan


def _geopoint(src: str, where: str, value: Any, need_alt: bool = True) -> GeoPoint:
    n = 3 if need_alt else 2
    if not isinstance(value, list) or len(value) != n or not all(_is_number(v) for v in value):
        raise _fail(src, where, f"expected [latitude, longitude{', altitude' if need_alt else ''}] numbers, "
                                f"got {value!r}")
    try:
        return GeoPoint(lat=value[0], lon=value[1], alt=value[2] if need_alt else 0.0)
    except ValidationError as e:
        raise _fail(src, where, f"{value!r}: {_first_error(e)}") from None


def _complex_item_count(raw: dict[str, Any]) -> int:
    """How many MAVLink items a ComplexItem expands to (QGroundControl's ``lastSequenceNumber`` arithmetic),
    used only to number the items that follow it when they lack a ``doJumpId``."""
    tsci = raw.get("TransectStyleComplexItem")
    if isinstance(tsci, dict) and isinstance(tsci.get("Items"), list):
        return max(len(tsci["Items"]), 1)
    if raw.get("complexItemType") == "StructureScan":
        poly, layers = raw.get("polygon"), raw.get("Layers")
        if isinstance(poly, list) and _is_number(layers):
            return max((len(poly) + 1 + 2) * int(layers) + 4, 1)
    return 1


def _parse_plan(text: str, src: str) -> MissionPlan:
    from aerodaas.model.jsonfile import JsonFileError, parse_json  # lazy: heavy numpy

    try:
        doc = parse_json(text, src)
    except JsonFileError as e:
        raise MissionFileError(str(e)) from None
    if not isinstance(doc, dict):
        raise _fail(src, "top level", f"expected a JSON object, got {type(doc).__name__}")
    if doc.get("fileType") != "Plan":
        raise _fail(src, "fileType", f"expected 'Plan', got {doc.get('fileType')!r}")
    if doc.get("version") != 1:
        raise _fail(src, "version", f"only .plan version 1 is supported, got {doc.get('version')!r}")
    mission = doc.get("mission")
    if not isinstance(mission, dict):
        raise _fail(src, "mission", f"expected a JSON object, got {mission!r:.80}")
    if mission.get("version") != 2:
        raise _fail(src, "mission.version", f"only mission version 2 is supported, got {mission.get('version')!r}")
    raw_items = mission.get("items")
    if not isinstance(raw_items, list):
        raise _fail(src, "mission.items", f"expected a list, got {raw_items!r:.80}")

    home = None
    if mission.get("plannedHomePosition") is not None:
        home = _geopoint(src, "mission.plannedHomePosition", mission["plannedHomePosition"])
    speeds: dict[str, float | None] = {}
    for key, name in (("cruiseSpeed", "cruise_speed"), ("hoverSpeed", "hover_speed")):
        v = mission.get(key)
        if v is not None and (not _is_number(v) or v < 0 or math.isinf(v)):
            raise _fail(src, f"mission.{key}", f"expected a speed >= 0 m/s, got {v!r}")
        speeds[name] = None if v is None else float(v)
    types: dict[str, int | None] = {}
    for key, name in (("firmwareType", "firmware_type"), ("vehicleType", "vehicle_type")):
        v = mission.get(key)
        if v is not None and (not isinstance(v, int) or isinstance(v, bool)):
            raise _fail(src, f"mission.{key}", f"expected an integer, got {v!r}")
        types[name] = v

    items: list[MissionItem] = []
    next_seq = 1  # QGroundControl numbers mission items from 1; the home position is 0
    for k, obj in enumerate(raw_items):
        where = f"mission.items[{k}]"
        if isinstance(obj, dict) and obj.get("type") == "ComplexItem":
            ctype = obj.get("complexItemType")
            if not isinstance(ctype, str):
                raise _fail(src, where, f"ComplexItem needs a string complexItemType, got {ctype!r}")
            seq = next_seq
            tsci = obj.get("TransectStyleComplexItem")
            if isinstance(tsci, dict) and isinstance(tsci.get("Items"), list) and tsci["Items"]:
                first = tsci["Items"][0]
                if isinstance(first, dict) and isinstance(first.get("doJumpId"), int) and first["doJumpId"] >= 0:
                    seq = first["doJumpId"]
            items.append(MissionItem(seq=seq, command=COMPLEX_ITEM_COMMAND, frame=MAV_FRAME_MISSION,
                                     raw=copy.deepcopy(obj)))
            next_seq = seq + _complex_item_count(obj)
        else:
            item = _parse_simple_item(src, where, obj, next_seq)
            items.append(item)
            next_seq = item.seq + 1

    geofence, breach_return = _parse_geofence(src, doc.get("geoFence"))
    rally = _parse_rally(src, doc.get("rallyPoints"))
    return MissionPlan(home=home, items=items, geofence=geofence, rally_points=rally,
                       breach_return=breach_return, source=src, **speeds, **types)


def _parse_geofence(src: str, fence: Any) -> tuple[GeofenceConfig, tuple[float, float, float] | None]:
    if fence is None:
        return GeofenceConfig(), None
    if not isinstance(fence, dict):
        raise _fail(src, "geoFence", f"expected a JSON object, got {fence!r:.80}")
    if fence.get("version") != 2:
        if any(fence.get(k) for k in ("polygons", "circles", "polygon", "circle", "breachReturn")):
            raise _fail(src, "geoFence.version", f"only geofence version 2 is supported, got {fence.get('version')!r} "
                                                 "(re-save the plan with a current QGroundControl)")
        return GeofenceConfig(), None
    polygons, circles = [], []
    for key in ("polygons", "circles"):
        if not isinstance(fence.get(key, []), list):
            raise _fail(src, f"geoFence.{key}", f"expected a list, got {fence.get(key)!r:.80}")
    for i, obj in enumerate(fence.get("polygons", [])):
        where = f"geoFence.polygons[{i}]"
        if not isinstance(obj, dict) or not isinstance(obj.get("polygon"), list):
            raise _fail(src, where, f"expected {{'polygon': [[lat, lon], ...], 'inclusion': bool}}, got {obj!r:.120}")
        if not isinstance(obj.get("inclusion"), bool):
            raise _fail(src, where + ".inclusion", f"expected true or false, got {obj.get('inclusion')!r}")
        pts = []
        for j, p in enumerate(obj["polygon"]):
            if not isinstance(p, list) or len(p) < 2 or not all(_is_number(v) for v in p[:2]):
                raise _fail(src, f"{where}.polygon[{j}]", f"expected [latitude, longitude], got {p!r}")
            pts.append((float(p[0]), float(p[1])))
        try:
            polygons.append(GeofencePolygon(points=pts, inclusion=obj["inclusion"]))
        except ValidationError as e:
            raise _fail(src, where, _first_error(e)) from None
    for i, obj in enumerate(fence.get("circles", [])):
        where = f"geoFence.circles[{i}]"
        circle = obj.get("circle") if isinstance(obj, dict) else None
        if not isinstance(circle, dict) or not isinstance(circle.get("center"), list) \
                or not _is_number(circle.get("radius")):
            raise _fail(src, where, f"expected {{'circle': {{'center': [lat, lon], 'radius': m}}, 'inclusion': bool}}, "
                                    f"got {obj!r:.120}")
        if not isinstance(obj.get("inclusion"), bool):
            raise _fail(src, where + ".inclusion", f"expected true or false, got {obj.get('inclusion')!r}")
        c = circle["center"]
        if len(c) < 2 or not all(_is_number(v) for v in c[:2]):
            raise _fail(src, where + ".circle.center", f"expected [latitude, longitude], got {c!r}")
        try:
            circles.append(GeofenceCircle(center=(float(c[0]), float(c[1])), radius=circle["radius"],
                                          inclusion=obj["inclusion"]))
        except ValidationError as e:
            raise _fail(src, where, _first_error(e)) from None
    breach = None
    if fence.get("breachReturn") is not None:
        p = _geopoint(src, "geoFence.breachReturn", fence["breachReturn"])
        breach = (p.lat, p.lon, p.alt)
    return GeofenceConfig(polygons=polygons, circles=circles), breach


def _parse_rally(src: str, rally: Any) -> list[tuple[float, float, float]]:
    if rally is None:
        return []
    if not isinstance(rally, dict):
        raise _fail(src, "rallyPoints", f"expected a JSON object, got {rally!r:.80}")
    if rally.get("version") != 2:
        if rally.get("points"):
            raise _fail(src, "rallyPoints.version", f"only rally point version 2 is supported, got "
                                                    f"{rally.get('version')!r}")
        return []
    points = rally.get("points", [])
    if not isinstance(points, list):
        raise _fail(src, "rallyPoints.points", f"expected a list, got {points!r:.80}")
    out = []
    for i, p in enumerate(points):
        g = _geopoint(src, f"rallyPoints.points[{i}]", p)
        out.append((g.lat, g.lon, g.alt))
    return out


def load_plan(path: str | Path) -> MissionPlan:
    """Read a QGroundControl ``.plan`` (``fileType`` "Plan", version 1, mission version 2, geoFence and
    rallyPoints version 2). SimpleItems become :class:`MissionItem` rows (``seq`` = ``doJumpId``), ComplexItems
    are kept verbatim. Raises :class:`MissionFileError` naming the file, the JSON path and the bad value."""
    path = Path(path)
    return _parse_plan(_read_text(path), str(path))


def _json_number(v: float | None) -> float | int | None:
    if v is None:
        return None
    return int(v) if float(v).is_integer() and abs(v) < 2 ** 53 else v


def plan_to_json(plan: MissionPlan) -> dict[str, Any]:
    """The ``.plan`` JSON object for ``plan`` (what :func:`save_plan` writes)."""
    src = plan.source or "<plan>"
    if plan.home is None:
        raise _fail(src, "home", "a QGroundControl .plan requires plannedHomePosition; set plan.home "
                                 "(latitude, longitude, AMSL altitude) before saving")
    items: list[dict[str, Any]] = []
    for item in plan.items:
        if item.raw is not None:
            items.append(copy.deepcopy(item.raw))
            continue
        items.append({
            "autoContinue": item.autocontinue, "command": item.command, "doJumpId": item.seq,
            "frame": item.frame, "params": [_json_number(p) for p in item.params], "type": "SimpleItem",
        })
    mission: dict[str, Any] = {
        "firmwareType": 12 if plan.firmware_type is None else plan.firmware_type,
        "items": items,
        "plannedHomePosition": [_json_number(plan.home.lat), _json_number(plan.home.lon),
                                _json_number(plan.home.alt)],
        "version": 2,
    }
    if plan.vehicle_type is not None:
        mission["vehicleType"] = plan.vehicle_type
    if plan.cruise_speed is not None:
        mission["cruiseSpeed"] = _json_number(plan.cruise_speed)
    if plan.hover_speed is not None:
        mission["hoverSpeed"] = _json_number(plan.hover_speed)
    fence: dict[str, Any] = {
        "circles": [{"circle": {"center": [_json_number(c.center[0]), _json_number(c.center[1])],
                                "radius": _json_number(c.radius)},
                     "inclusion": c.inclusion, "version": 1} for c in plan.geofence.circles],
        "polygons": [{"inclusion": p.inclusion,
                      "polygon": [[_json_number(a), _json_number(b)] for a, b in p.points],
                      "version": 1} for p in plan.geofence.polygons],
        "version": 2,
    }
    if plan.breach_return is not None:
        fence["breachReturn"] = [_json_number(v) for v in plan.breach_return]
    return {
        "fileType": "Plan",
        "geoFence": fence,
        "groundStation": "AeroDaaS",
        "mission": mission,
        "rallyPoints": {"points": [[_json_number(v) for v in p] for p in plan.rally_points], "version": 2},
        "version": 1,
    }


def save_plan(plan: MissionPlan, path: str | Path) -> None:
    """Write ``plan`` as a QGroundControl ``.plan`` (JSON, keys sorted, 4-space indent as QGroundControl does).
    ComplexItems are written back verbatim. Requires ``plan.home`` (QGroundControl's required
    ``plannedHomePosition``); raises :class:`MissionFileError` otherwise."""
    doc = plan_to_json(plan)
    Path(path).write_text(json.dumps(doc, indent=4, sort_keys=True, allow_nan=False) + "\n", encoding="utf-8")
