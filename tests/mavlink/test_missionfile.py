"""QGroundControl .plan and QGC WPL 110 import/export (aerodaas.missionfile).

Real sample files are read from ``$AERODAAS_DATA_DIR/missions`` (default ``<repo>/../shared/data/missions``);
tests that need them are skipped, with the path in the reason, when the folder is absent.
"""
from __future__ import annotations

import json
import math

import pytest

from aerodaas.missionfile import (
    PAYLOAD_COMMANDS,
    FlightPlan,
    MissionFileError,
    MissionItem,
    MissionPlan,
    load_mission,
    load_plan,
    load_wpl,
    navigation_to_plan,
    plan_to_flight,
    plan_to_navigation,
    save_plan,
    save_wpl,
)
from aerodaas.model.geo import enu_to_geodetic, geodetic_to_enu
from aerodaas.model.types import AeroNavigation, GeoPoint, NavigationType, SchedulingType, VelocityCommand, Waypoint
from aerodaas.navigation.geofence import GeofenceCircle, GeofenceConfig, GeofencePolygon
from tests.conftest import DATA_DIR, needs_path, skip_or_fail

MISSIONS = DATA_DIR / "missions"
KNOWN = ["dronekit_mpmission.txt", "mavsdk_mission_planner_sample.txt", "mavsdk_qgroundcontrol_sample.plan",
         "mavsdk_qgroundcontrol_sample_with_structured_scan.plan", "mavsdk_qgroundcontrol_sample_with_survey.plan",
         "qgc_test_simple_square.plan"]
needs_missions = needs_path(MISSIONS, reason="the sample missions of the shared data (set AERODAAS_DATA_DIR)")


def _mission_files() -> list[str]:
    if not MISSIONS.is_dir():
        return KNOWN
    return sorted(p.name for p in MISSIONS.iterdir() if p.is_file() and not p.name.startswith("LICENSE"))


def sample(name: str):
    path = MISSIONS / name
    if not path.is_file():
        skip_or_fail(f"sample mission not found: {path} (set AERODAAS_DATA_DIR)")
    return path


HOME = GeoPoint(lat=47.397742, lon=8.545594, alt=488.0)


def item(seq: int, command: int, frame: int = 3, params=(0, 0, 0, None, HOME.lat, HOME.lon, 20.0)) -> MissionItem:
    return MissionItem(seq=seq, command=command, frame=frame, params=list(params))


def wp_params(x: float, y: float, z: float, hold: float = 0.0, radius: float = 0.0):
    g = enu_to_geodetic(x, y, 0.0, HOME)
    return (hold, radius, 0, None, g.lat, g.lon, z)


# --- round trips on every sample file --------------------------------------------------------------------


@needs_missions
def test_every_sample_file_is_covered():
    assert set(KNOWN) <= set(_mission_files())


@needs_missions
@pytest.mark.parametrize("name", _mission_files())
def test_round_trip_same_format_is_lossless(name, tmp_path):
    src = sample(name)
    plan = load_mission(src)
    out = tmp_path / src.name
    (save_plan if src.suffix == ".plan" else save_wpl)(plan, out)
    again = load_mission(out)
    assert again.same_mission(plan)
    assert again.items == plan.items and again.home == plan.home and again.geofence == plan.geofence
    if src.suffix == ".plan":  # complex items are written back verbatim
        original = json.loads(src.read_text())["mission"]["items"]
        written = json.loads(out.read_text())["mission"]["items"]
        assert [o for o in original if o["type"] == "ComplexItem"] == [w for w in written if w["type"] == "ComplexItem"]


@needs_missions
@pytest.mark.parametrize("name", _mission_files())
def test_round_trip_through_the_other_format(name, tmp_path):
    plan = load_mission(sample(name))
    if name.endswith(".plan"):
        save_wpl(plan, tmp_path / "m.waypoints")  # complex items expanded into their MAVLink items
        back = load_wpl(tmp_path / "m.waypoints")
        assert back.items == plan.expanded_items()
        assert back.home == plan.home
    else:
        if plan.home is None:  # a .plan needs plannedHomePosition
            with pytest.raises(MissionFileError, match="plannedHomePosition"):
                save_plan(plan, tmp_path / "m.plan")
            plan = plan.model_copy(update={"home": GeoPoint(lat=47.3978101, lon=8.545538, alt=0.0)})
        save_plan(plan, tmp_path / "m.plan")
        back = load_plan(tmp_path / "m.plan")
        assert back.items == plan.items and back.home == plan.home
        save_wpl(back, tmp_path / "again.txt")
        assert load_wpl(tmp_path / "again.txt").same_mission(plan)


@needs_missions
@pytest.mark.parametrize("name", ["qgc_test_simple_square.plan", "mavsdk_qgroundcontrol_sample.plan"])
def test_plan_to_wpl_to_plan_keeps_simple_missions(name, tmp_path):
    plan = load_plan(sample(name))
    save_wpl(plan, tmp_path / "m.txt")
    save_plan(load_wpl(tmp_path / "m.txt"), tmp_path / "m.plan")
    back = load_plan(tmp_path / "m.plan")
    assert back.items == plan.items and back.home == plan.home and back.geofence == plan.geofence
    a, b = (plan_to_flight(p, skip_commands=PAYLOAD_COMMANDS) for p in (back, plan))
    assert a.navigation.waypoints == b.navigation.waypoints and a.final_action == b.final_action
    assert a.skipped == b.skipped


@needs_missions
def test_exported_plan_has_the_keys_qgroundcontrol_needs(tmp_path):
    plan = load_plan(sample("mavsdk_qgroundcontrol_sample_with_survey.plan"))
    save_plan(plan, tmp_path / "m.plan")
    doc = json.loads((tmp_path / "m.plan").read_text())
    assert doc["fileType"] == "Plan" and doc["version"] == 1
    mission = doc["mission"]
    assert mission["version"] == 2 and isinstance(mission["firmwareType"], int)
    assert mission["plannedHomePosition"] == [47.39801775617688, 8.545149580000002, 483.4261075265049]
    simple = [i for i in mission["items"] if i["type"] == "SimpleItem"]
    assert simple
    for it in simple:
        assert {"type", "command", "frame", "params", "autoContinue", "doJumpId"} <= set(it)
        assert len(it["params"]) == 7 and isinstance(it["autoContinue"], bool)
    assert doc["geoFence"] == {"circles": [], "polygons": [], "version": 2}
    assert doc["rallyPoints"] == {"points": [], "version": 2}


# --- what the samples contain --------------------------------------------------------------------------------


@needs_missions
def test_sample_contents_are_read_as_written():
    square = load_plan(sample("qgc_test_simple_square.plan"))
    assert square.home == GeoPoint(lat=47.397742, lon=8.545594, alt=488)
    assert [i.command for i in square.items] == [22, 16, 16, 16, 16]
    assert [i.seq for i in square.items] == [1, 2, 3, 4, 5]
    assert square.items[1].params == [0, 0, 0, None, 47.398742, 8.546594, 20]
    assert (square.cruise_speed, square.hover_speed, square.firmware_type) == (15, 5, 12)

    dk = load_wpl(sample("dronekit_mpmission.txt"))  # row 0 is the home position (AMSL)
    assert dk.home == GeoPoint(lat=-35.363262, lon=149.165237, alt=584.0)
    assert [i.command for i in dk.items] == [22, 16, 16, 16, 16, 16] and {i.frame for i in dk.items} == {0}

    mp = load_wpl(sample("mavsdk_mission_planner_sample.txt"))  # PX4 style: row 0 is a takeoff, no home row
    assert mp.home is None
    assert [(i.seq, i.command, i.frame) for i in mp.items] == [(1, 22, 5), (2, 16, 5), (3, 16, 5), (4, 20, 5)]
    for name in KNOWN:  # none of the samples defines a geofence (the fence tests build their own)
        assert load_mission(sample(name)).geofence == GeofenceConfig()


@needs_missions
def test_survey_expands_to_the_items_it_carries():
    plan = load_plan(sample("mavsdk_qgroundcontrol_sample_with_survey.plan"))
    assert [i.is_complex for i in plan.items] == [False, True] and plan.items[1].complex_type == "survey"
    embedded = plan.items[1].raw["TransectStyleComplexItem"]["Items"]
    expanded = plan.expanded_items()
    assert len(expanded) == 1 + len(embedded) == 13
    for it, raw in zip(expanded[1:], embedded):
        assert (it.seq, it.command, it.frame) == (raw["doJumpId"], raw["command"], raw["frame"])
    flight = plan_to_flight(plan, skip_commands=PAYLOAD_COMMANDS)
    visual = plan.items[1].raw["TransectStyleComplexItem"]["VisualTransectPoints"]
    assert [(w.x, w.y) for w in flight.navigation.waypoints] == [tuple(p) for p in visual]
    assert {w.z for w in flight.navigation.waypoints} == {50.0}
    assert flight.final_action == "hover"
    assert len(flight.skipped) == 5 and "MAV_CMD_SET_CAMERA_MODE (530)" in flight.skipped[0]


@needs_missions
def test_structure_scan_expands_like_qgroundcontrol():
    plan = load_plan(sample("mavsdk_qgroundcontrol_sample_with_structured_scan.plan"))
    raw = plan.items[1].raw
    items = plan.expanded_items()[1:]
    # StructureScanComplexItem::lastSequenceNumber: (vertices + 1 + 2) per layer + ROI pair + entrance/exit
    assert len(items) == (4 + 1 + 2) * raw["Layers"] + 4
    assert [i.seq for i in items] == list(range(2, 2 + len(items)))
    assert [i.command for i in items[:3]] == [16, 196, 16] and [i.command for i in items[-2:]] == [197, 16]
    waypoints = [i for i in items if i.command == 16]
    assert waypoints[0].params[4:] == waypoints[-1].params[4:] and waypoints[0].params[6] == raw["EntranceAltitude"]
    # StartFromTop: layers at StructureHeight - frontal/2, then one frontal footprint lower
    assert [w.params[6] for w in waypoints[1:-1]] == [87.5] * 5 + [62.5] * 5
    assert [i.params[0] for i in items if i.command == 206] == [25, 0, 25, 0]
    # the flight polygon is the structure polygon pushed DistanceToSurface (50 m) outward, edge by edge
    origin = GeoPoint(lat=raw["polygon"][0][0], lon=raw["polygon"][0][1], alt=0.0)
    s = [geodetic_to_enu(a, b, 0.0, origin)[:2] for a, b in raw["polygon"]]
    f = [geodetic_to_enu(w.params[4], w.params[5], 0.0, origin)[:2] for w in waypoints[1:5]]
    for k in range(4):
        (x0, y0), (x1, y1) = s[k], s[(k + 1) % 4]
        nx, ny = -(y1 - y0), (x1 - x0)  # left-hand normal = outward for the clockwise (map view) outline
        norm = math.hypot(nx, ny)
        for px, py in (f[k], f[(k + 1) % 4]):
            assert ((px - x0) * nx + (py - y0) * ny) / norm == pytest.approx(50.0, abs=1e-6)


# --- conversion to AeroDaaS navigation ------------------------------------------------------------------------


@needs_missions
def test_simple_square_becomes_absolute_waypoints():
    flight = plan_to_flight(load_plan(sample("qgc_test_simple_square.plan")))
    nav = flight.navigation
    assert isinstance(flight, FlightPlan) and flight.final_action == "hover" and flight.skipped == []
    assert nav.scheduling_type == SchedulingType.ORDERED and nav.navigation_type == NavigationType.DISTANCE_DRIVEN
    assert [w.id for w in nav.waypoints] == ["item1", "item2", "item3", "item4", "item5"]
    assert all(w.waypoint_type == "absolute" and w.z == 20 for w in nav.waypoints)
    assert (nav.waypoints[1].x, nav.waypoints[1].y) == (47.398742, 8.546594)
    assert plan_to_navigation(load_plan(sample("qgc_test_simple_square.plan"))) == nav


@needs_missions
def test_unsupported_command_is_named_not_dropped():
    path = sample("mavsdk_qgroundcontrol_sample.plan")
    with pytest.raises(MissionFileError) as e:
        plan_to_flight(load_plan(path))
    msg = str(e.value)
    assert str(path) in msg and "item 3" in msg and "MAV_CMD_IMAGE_START_CAPTURE (2000)" in msg
    assert "PAYLOAD_COMMANDS" in msg
    flight = plan_to_flight(load_plan(path), skip_commands=PAYLOAD_COMMANDS)
    assert flight.final_action == "rtl"
    assert flight.skipped == ["item 3 (MAV_CMD_IMAGE_START_CAPTURE (2000)) skipped"]
    assert [w.id for w in flight.navigation.waypoints] == ["item1", "item2", "item4", "item5"]
    assert flight.navigation.waypoints[0].z == 50  # takeoff at its own position and altitude
    with pytest.raises(ValueError, match="NAV_LAND"):
        plan_to_flight(load_plan(path), skip_commands={21})


@needs_missions
def test_amsl_altitudes_need_home_and_are_converted_with_it():
    mp = load_wpl(sample("mavsdk_mission_planner_sample.txt"))  # MAV_FRAME_GLOBAL_INT (5): AMSL
    with pytest.raises(MissionFileError, match=r"item 1 \(MAV_CMD_NAV_TAKEOFF \(22\)\).*above mean sea level.*home"):
        plan_to_flight(mp)
    flight = plan_to_flight(mp, GeoPoint(lat=47.3978101, lon=8.545538, alt=5.0))
    assert [w.z for w in flight.navigation.waypoints] == [10.0, 10.0, 10.0] and flight.final_action == "rtl"

    dk = load_wpl(sample("dronekit_mpmission.txt"))  # frame 0, z = 100 m AMSL under a 584 m AMSL home
    with pytest.raises(MissionFileError, match=r"item 1 .*-484 m above home is below min_altitude 0 m"):
        plan_to_flight(dk)
    assert plan_to_flight(dk, min_altitude=None).navigation.waypoints[0].z == -484.0


def test_flight_items_map_to_waypoints_and_terminal_actions():
    far = enu_to_geodetic(100, 0, 0, HOME)
    plan = MissionPlan(home=HOME, items=[
        item(1, 22, params=(0, 0, 0, None, 0, 0, 15)),  # takeoff at home (lat/lon 0)
        item(2, 178, 2, (1, 4.5, -1, 0, 0, 0, 0)),  # DO_CHANGE_SPEED ground speed 4.5 m/s
        item(3, 16, params=wp_params(20, 0, 25, hold=3, radius=2)),
        item(4, 19, params=(7, 0, 0, None, None, None, 25)),  # loiter 7 s where it is
        item(5, 178, 2, (1, -2, -1, 0, 0, 0, 0)),  # back to the default speed
        item(6, 16, 0, (0, 0, 0, None, far.lat, far.lon, HOME.alt + 30)),  # AMSL altitude
        item(7, 21, params=(0, 0, 0, None, *ll_of(100, 50), 0)),  # land elsewhere: approach waypoint first
    ])
    flight = plan_to_flight(plan)
    w = flight.navigation.waypoints
    assert [x.id for x in w] == ["item1", "item3", "item4", "item6", "item7_approach"]
    assert (w[0].x, w[0].y, w[0].z) == (HOME.lat, HOME.lon, 15)
    assert (w[1].hover_duration, w[1].acceptance_radius, w[1].speed) == (3, 2, 4.5)
    assert (w[2].x, w[2].y, w[2].hover_duration, w[2].speed) == (w[1].x, w[1].y, 7, 4.5)
    assert w[3].z == pytest.approx(30.0) and w[3].speed is None
    assert w[4].z == pytest.approx(30.0) and flight.final_action == "land"
    assert w[1].to_local(HOME)[:2] == pytest.approx((20, 0), abs=1e-6)


def ll_of(x: float, y: float) -> tuple[float, float]:
    g = enu_to_geodetic(x, y, 0.0, HOME)
    return (g.lat, g.lon)


@pytest.mark.parametrize("items, pattern", [
    ([item(1, 20, 2, (0,) * 7), item(2, 16)], r"item 2 .*NAV_WAYPOINT.*after the terminal item 1"),
    ([item(1, 17), item(2, 16)], r"item 1 \(MAV_CMD_NAV_LOITER_UNLIM \(17\)\): loiters forever.*item 2"),
    ([item(1, 16), item(2, 177, 2, (1, 3, 0, 0, 0, 0, 0))], r"item 2 \(MAV_CMD_DO_JUMP \(177\)\).*not supported"),
    ([item(1, 18)], r"item 1 \(MAV_CMD_NAV_LOITER_TURNS \(18\)\).*not supported"),
    ([item(1, 16, 10)], r"item 1 .*MAV_FRAME_GLOBAL_TERRAIN_ALT \(10\).*terrain"),
    ([item(1, 16, params=(0, 0, 0, None, 0, 0, 20))], r"item 1 .*latitude/longitude not set"),
    ([item(1, 16, params=(-1, 0, 0, None, HOME.lat, HOME.lon, 20))], r"item 1 .*param1 .*-1"),
    ([item(1, 178, 2, (2, 3, -1, 0, 0, 0, 0))], r"item 1 .*DO_CHANGE_SPEED.*speed type 2"),
])
def test_unflyable_items_are_rejected_by_name(items, pattern):
    with pytest.raises(MissionFileError, match=pattern):
        plan_to_flight(MissionPlan(home=HOME, items=items, source="demo.plan"))


def test_loiter_unlimited_last_means_hover_and_empty_plans_work():
    flight = plan_to_flight(MissionPlan(home=HOME, items=[item(1, 22), item(2, 17)]))
    assert flight.final_action == "hover" and [w.id for w in flight.navigation.waypoints] == ["item1", "item2"]
    rtl = plan_to_flight(MissionPlan(items=[item(1, 20, 2, (0,) * 7)]))
    assert rtl.final_action == "rtl" and rtl.navigation.waypoints == [] and rtl.home is None


def test_unexpandable_complex_items_are_kept_in_plans_and_rejected_elsewhere(tmp_path):
    landing = {"type": "ComplexItem", "complexItemType": "fwLandingPattern", "version": 2, "landCoordinate": [1, 2, 0]}
    scan = {"type": "ComplexItem", "complexItemType": "StructureScan", "version": 3, "Layers": 3,
            "ScanBottomAlt": 0, "StructureHeight": 20, "EntranceAltitude": 30, "GimbalPitch": 0,
            "StartFromTop": False, "polygon": [list(ll_of(0, 0)), list(ll_of(10, 0)), list(ll_of(10, -10))],
            "CameraCalc": {"AdjustedFootprintFrontal": 10, "AdjustedFootprintSide": 10, "DistanceToSurface": 5}}
    for raw, pattern in [(landing, r"items\[0\] \(ComplexItem 'fwLandingPattern', item 1\): AeroDaaS cannot expand"),
                         (scan, r"Layers = 3 disagrees .* = 2")]:
        plan = MissionPlan(home=HOME, items=[MissionItem(seq=1, command=0, frame=2, raw=raw)], source="x.plan")
        save_plan(plan, tmp_path / "x.plan")
        assert load_plan(tmp_path / "x.plan").items == plan.items
        with pytest.raises(MissionFileError, match=pattern):
            save_wpl(plan, tmp_path / "x.txt")
        with pytest.raises(MissionFileError, match=pattern):
            plan_to_flight(plan)
    scan["Layers"] = 2
    ok = MissionPlan(home=HOME, items=[MissionItem(seq=1, command=0, frame=2, raw=scan)])
    alts = [i.params[6] for i in ok.expanded_items() if i.command == 16]
    assert alts == [30] + [5] * 4 + [15] * 4 + [30]  # bottom-up layers at ScanBottomAlt + frontal/2, + frontal


# --- AeroDaaS navigation -> plan ------------------------------------------------------------------------------


def test_navigation_to_plan_and_back(tmp_path):
    nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, [
        Waypoint(id="a", x=30, y=-10, z=15, hover_duration=2),
        Waypoint(id="b", x=47.3980, y=8.5460, z=25, waypoint_type="absolute", speed=3.0, acceptance_radius=1.5),
        Waypoint(id="c", x=-20, y=40, z=20),
    ], SchedulingType.ORDERED)
    fence = GeofenceConfig(polygons=[GeofencePolygon(points=[ll_of(-100, 100), ll_of(100, 100), ll_of(100, -100),
                                                             ll_of(-100, -100)])],
                           circles=[GeofenceCircle(center=ll_of(60, 60), radius=15, inclusion=False)])
    plan = navigation_to_plan(nav, HOME, "rtl", fence, takeoff_altitude=10)
    assert [i.command for i in plan.items] == [22, 16, 178, 16, 178, 16, 20]
    assert plan.items[2].params[:2] == [1, 3.0] and plan.items[4].params[:2] == [1, -2]
    for fmt in ("plan", "txt"):
        path = tmp_path / f"nav.{fmt}"
        (save_plan if fmt == "plan" else save_wpl)(plan, path)
        back = load_mission(path)
        assert back.items == plan.items and back.home == HOME
        assert back.geofence == (fence if fmt == "plan" else GeofenceConfig())  # WPL cannot store a fence
    flight = plan_to_flight(load_plan(tmp_path / "nav.plan"))
    assert flight.final_action == "rtl" and flight.geofence == fence
    w = flight.navigation.waypoints
    assert [x.id for x in w] == ["item1", "item2", "item4", "item6"]
    assert w[1].to_local(HOME) == pytest.approx((30, -10, 15), abs=1e-6) and w[1].hover_duration == 2
    assert (w[2].x, w[2].y, w[2].speed, w[2].acceptance_radius) == (47.3980, 8.5460, 3.0, 1.5)
    assert w[3].to_local(HOME) == pytest.approx((-20, 40, 20), abs=1e-6) and w[3].speed is None


def test_navigation_with_velocity_commands_is_rejected():
    nav = AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [VelocityCommand(id="v1", vx=1.0)])
    with pytest.raises(MissionFileError, match="velocity command 'v1'"):
        navigation_to_plan(nav, HOME)


def test_plan_geofence_is_checked_for_waypoints_and_legs(tmp_path):
    fence = GeofenceConfig(polygons=[GeofencePolygon(points=[ll_of(-50, 50), ll_of(50, 50), ll_of(50, -50),
                                                             ll_of(-50, -50)]),
                                     GeofencePolygon(points=[ll_of(10, 10), ll_of(20, 10), ll_of(20, -10),
                                                             ll_of(10, -10)], inclusion=False)])
    ok = [item(1, 22, params=(0, 0, 0, None, 0, 0, 10)), item(2, 16, params=wp_params(-20, 30, 10))]
    assert plan_to_flight(MissionPlan(home=HOME, items=ok, geofence=fence)).final_action == "hover"
    inside = ok + [item(3, 16, params=wp_params(15, 0, 10))]
    with pytest.raises(MissionFileError, match=r"geofence: item3: inside exclusion polygon 1"):
        plan_to_flight(MissionPlan(home=HOME, items=inside, geofence=fence))
    across = ok + [item(3, 16, params=wp_params(0, 0, 10)), item(4, 16, params=wp_params(30, 0, 10))]
    with pytest.raises(MissionFileError, match=r"geofence: leg item3 -> item4: leg crosses exclusion polygon 1"):
        plan_to_flight(MissionPlan(home=HOME, items=across, geofence=fence))
    outside = ok + [item(3, 16, params=wp_params(80, 0, 10))]
    with pytest.raises(MissionFileError, match=r"geofence: item3: outside inclusion polygon 0"):
        plan_to_flight(MissionPlan(home=HOME, items=outside, geofence=fence))
    assert plan_to_flight(MissionPlan(home=HOME, items=across, geofence=fence), check_geofence=False)
    save_plan(MissionPlan(home=HOME, items=ok, geofence=fence), tmp_path / "f.plan")
    doc = json.loads((tmp_path / "f.plan").read_text())["geoFence"]
    assert doc["version"] == 2 and doc["circles"] == []
    assert [(p["inclusion"], p["version"], len(p["polygon"])) for p in doc["polygons"]] == [(True, 1, 4), (False, 1, 4)]


# --- bad input ------------------------------------------------------------------------------------------------

GOOD_ROW = "1\t0\t3\t16\t0\t0\t0\t0\t47.39\t8.54\t20\t1"


def write(tmp_path, name: str, text: str, newline: str = "\n"):
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode())
    return path


@pytest.mark.parametrize("body, pattern", [
    ("QGC WPL 110\n" + GOOD_ROW + "\n1\t0\t3\t16\t0\t0\t0\t47.39\t8.54\t20\t1\n", r"line 3: expected 12 .*got 11"),
    ("QGC WPL 100\n" + GOOD_ROW + "\n", r"line 1: expected the header 'QGC WPL 110', got 'QGC WPL 100'"),
    ("waypoints\n" + GOOD_ROW + "\n", r"line 1: .*'waypoints'"),
    ("QGC WPL 110\n" + GOOD_ROW.replace("47.39", "97.39") + "\n",
     r"line 2 \(MAV_CMD_NAV_WAYPOINT \(16\)\): latitude \(x\) 97.39 is outside \[-90, 90\]"),
    ("QGC WPL 110\n" + GOOD_ROW.replace("\t3\t16", "\t1\t16") + "\n", r"line 2: MAV_FRAME_LOCAL_NED \(1\) is not a mission"),
    ("QGC WPL 110\n" + GOOD_ROW.replace("\t3\t16", "\t99\t16") + "\n", r"line 2: unknown frame 99"),
    ("QGC WPL 110\n" + GOOD_ROW.replace("\t20\t", "\tabc\t") + "\n", r"line 2 .*z \(altitude\) must be a number, got 'abc'"),
    ("QGC WPL 110\n" + GOOD_ROW.replace("\t16\t", "\tx\t") + "\n", r"line 2: command must be an integer, got 'x'"),
    ("QGC WPL 110\n0\t1\t3\t16\t0\t0\t0\t0\t47.39\t8.54\t20\t1\n", r"line 2 \(home position\).*MAV_FRAME_GLOBAL \(0\)"),
])
def test_malformed_wpl_is_rejected_with_file_line_and_value(tmp_path, body, pattern):
    path = write(tmp_path, "bad.waypoints", body)
    with pytest.raises(MissionFileError, match=pattern) as e:
        load_mission(path) if body.startswith("QGC") else load_wpl(path)
    assert str(e.value).startswith(str(path))


@pytest.mark.parametrize("seqs, line, said", [((1, 1, 5), 4, "seq 1 out of order: the row after seq 1 must be seq 2"),
                                              ((1, 2, 5), 5, "seq 5 out of order: the row after seq 2 must be seq 3"),
                                              ((1, 3), 4, "seq 3 out of order")])
def test_wpl_rows_out_of_sequence_are_refused_not_renumbered(tmp_path, seqs, line, said):
    """A WPL numbered 1, 1, 5 was renumbered 1, 2, 3 silently (and a DO_JUMP target with it)."""
    rows = ["QGC WPL 110", "0\t1\t0\t16\t0\t0\t0\t0\t47.3977\t8.5456\t488\t1"]
    rows += [f"{q}\t0\t3\t16\t0\t0\t0\t0\t47.3978\t8.5456\t20\t1" for q in seqs]
    path = write(tmp_path, "seq.waypoints", "\n".join(rows) + "\n")
    with pytest.raises(MissionFileError, match=rf"line {line} .*{said}"):
        load_wpl(path)


def test_wpl_without_a_home_row_may_count_from_0_or_1(tmp_path):
    for first in (0, 1):
        rows = ["QGC WPL 110", f"{first}\t0\t3\t22\t0\t0\t0\t0\t47.3977\t8.5456\t10\t1"]  # take-off: no home row
        rows += [f"{first + 1}\t0\t3\t16\t0\t0\t0\t0\t47.3978\t8.5456\t20\t1"]
        plan = load_wpl(write(tmp_path, f"nohome{first}.waypoints", "\n".join(rows) + "\n"))
        assert [i.seq for i in plan.items] == [1, 2] and plan.home is None
    with pytest.raises(MissionFileError, match=r"line 2 .*: seq must start at 0 \(the home row\) or 1, got 2"):
        load_wpl(write(tmp_path, "from2.waypoints", "QGC WPL 110\n2\t0\t3\t22\t0\t0\t0\t0\t47.3977\t8.5456\t10\t1\n"))


def test_wpl_accepts_crlf_blank_lines_and_a_bom(tmp_path):
    text = "\ufeffQGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47.3977\t8.5455\t488\t1\n\n" + GOOD_ROW + "\n"
    plan = load_wpl(write(tmp_path, "crlf.txt", text, newline="\r\n"))
    assert plan.home == GeoPoint(lat=47.3977, lon=8.5455, alt=488) and len(plan.items) == 1
    assert isinstance(MissionFileError("x"), ValueError)


def _plan_doc(**mission_items) -> dict:
    doc = {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
           "geoFence": {"circles": [], "polygons": [], "version": 2}, "rallyPoints": {"points": [], "version": 2},
           "mission": {"version": 2, "firmwareType": 12, "plannedHomePosition": [47.39, 8.54, 488],
                       "items": [{"type": "SimpleItem", "command": 16, "frame": 3, "doJumpId": 1, "autoContinue": True,
                                  "params": [0, 0, 0, None, 47.39, 8.54, 20]}]}}
    for key, value in mission_items.items():
        target = doc["mission"]["items"][0] if key in ("command", "frame", "params") else doc
        if key == "home":
            doc["mission"]["plannedHomePosition"] = value
        elif key == "fence":
            doc["geoFence"] = value
        else:
            target[key] = value
    return doc


@pytest.mark.parametrize("doc, pattern", [
    (_plan_doc(params=[0, 0, 0, None, 91.5, 8.54, 20]),
     r"mission.items\[0\] \(doJumpId 1, MAV_CMD_NAV_WAYPOINT \(16\)\): latitude \(x\) 91.5 is outside"),
    (_plan_doc(frame=4), r"mission.items\[0\] \(doJumpId 1\): MAV_FRAME_LOCAL_ENU \(4\) is not a mission frame"),
    (_plan_doc(params=[0, 0, 0, 20]), r"params must be a list of 7 values"),
    (_plan_doc(params=[0, "x", 0, None, 47.39, 8.54, 20]), r"params\[1\] must be a number or null, got 'x'"),
    (_plan_doc(fileType="Mission"), r"fileType: expected 'Plan', got 'Mission'"),
    (_plan_doc(version=2), r"version: only .plan version 1"),
    (_plan_doc(home=[47.39, 188.0, 488]), r"mission.plannedHomePosition: .*188"),
    (_plan_doc(fence={"version": 2, "circles": [], "polygons": [{"polygon": [[1, 2], [1, 3]], "inclusion": True}]}),
     r"geoFence.polygons\[0\]: .*at least 3"),
    (_plan_doc(fence={"version": 2, "polygons": [], "circles": [{"circle": {"center": [1, 2], "radius": -5},
                                                                 "inclusion": False}]}),
     r"geoFence.circles\[0\]: radius"),
])
def test_malformed_plan_is_rejected_with_path_and_value(tmp_path, doc, pattern):
    path = write(tmp_path, "bad.plan", json.dumps(doc))
    with pytest.raises(MissionFileError, match=pattern) as e:
        load_mission(path)
    assert str(e.value).startswith(str(path))


def test_invalid_json_names_line_and_column(tmp_path):
    path = write(tmp_path, "broken.plan", '{\n  "fileType": "Plan",\n  "version": 1,,\n}')
    with pytest.raises(MissionFileError, match=r"broken.plan: line 3 column 16: invalid JSON"):
        load_plan(path)


def test_plan_geofence_and_rally_points_round_trip(tmp_path):
    doc = _plan_doc(fence={"version": 2, "breachReturn": [47.39, 8.54, 30],
                           "polygons": [{"version": 1, "inclusion": False,
                                         "polygon": [[47.390, 8.540], [47.391, 8.540], [47.391, 8.541]]}],
                           "circles": [{"version": 1, "inclusion": True,
                                        "circle": {"center": [47.39, 8.54], "radius": 319.85}}]})
    doc["rallyPoints"]["points"] = [[47.3976, 8.5509, 50]]
    plan = load_plan(write(tmp_path, "fence.plan", json.dumps(doc)))
    assert plan.geofence.polygons[0].inclusion is False and plan.geofence.circles[0].radius == 319.85
    assert plan.breach_return == (47.39, 8.54, 30) and plan.rally_points == [(47.3976, 8.5509, 50)]
    save_plan(plan, tmp_path / "again.plan")
    assert load_plan(tmp_path / "again.plan").same_mission(plan)


def test_navigation_ending_with_an_action_command_exports_that_action():
    from aerodaas.model.types import ActionCommand as action_cls
    nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=5, y=5, z=10),
                                                          action_cls(id="home", action="rtl")])
    plan = navigation_to_plan(nav, HOME, "land")
    assert [i.command for i in plan.items] == [16, 20]
    assert plan_to_flight(plan).final_action == "rtl"
    early = AeroNavigation(NavigationType.DISTANCE_DRIVEN, [action_cls(id="stop", action="land"),
                                                            Waypoint(id="a", x=5, y=5, z=10)])
    with pytest.raises(MissionFileError, match="land action 'stop' ends the flight.*'a'"):
        navigation_to_plan(early, HOME)
