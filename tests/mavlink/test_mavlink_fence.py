"""The autopilot's own geofence against the emulated ArduPilot and PX4 vehicles: the robot's
``safety.geofence`` goes up as MAV_MISSION_TYPE_FENCE items with the fence parameters on connect, is read back and
checked (a mismatch refuses to fly), is restored on close when asked, and ``aerodaas mission upload`` sends a
``.plan``'s fence and rally points. What the vehicle holds is read from the emulator's own state (its stored
items and parameters), not through the backend's download."""
from __future__ import annotations

import json

import pytest

from aerodaas.backends import BackendError, make_backend
from aerodaas.cli import main
from aerodaas.config import MavlinkConfig, RobotConfig
from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
from aerodaas.model.geo import enu_to_geodetic
from aerodaas.model.types import GeoPoint
from tests.conftest import DATA_DIR

HOME = GeoPoint(lat=47.397742, lon=8.545594, alt=488.0)
SQUARE = DATA_DIR / "missions" / "qgc_test_simple_square.plan"


def _ll(e: float, n: float) -> tuple[float, float]:
    g = enu_to_geodetic(e, n, 0.0, HOME)
    return (g.lat, g.lon)


#: an inclusion square of 60 m around home, an exclusion circle of 4 m at (10, 10), an inclusion circle of 40 m
FENCE = {"polygons": [{"points": [_ll(-30, -30), _ll(30, -30), _ll(30, 30), _ll(-30, 30)], "inclusion": True}],
         "circles": [{"center": _ll(10, 10), "radius": 4.5, "inclusion": False},
                     {"center": _ll(0, 0), "radius": 40.0, "inclusion": True}]}
#: the same without the inclusion circle: one inclusion zone, what a PX4 vehicle takes (it intersects inclusion zones)
FENCE_ONE = {"polygons": FENCE["polygons"], "circles": FENCE["circles"][:1]}
#: the fence items the vehicle must hold: (command, param1, lat e7, lon e7)
WANT_ONE = ([(5001, 4.0, round(a * 1e7), round(b * 1e7)) for a, b in FENCE["polygons"][0]["points"]]
            + [(5004, 4.5, round(FENCE["circles"][0]["center"][0] * 1e7),
                round(FENCE["circles"][0]["center"][1] * 1e7))])
WANT = WANT_ONE + [(5003, 40.0, round(HOME.lat * 1e7), round(HOME.lon * 1e7))]
#: the default fence of each autopilot's vehicle in these tests, and the items it leaves on the vehicle
FENCES = {"ardupilot": (FENCE, WANT), "px4": (FENCE_ONE, WANT_ONE)}
_DEFAULT = object()


@pytest.fixture
def vehicle():
    made: list = []

    def make(autopilot: str, fence: dict | None = _DEFAULT, mavlink: dict | None = None, **safety):
        fence = FENCES[autopilot][0] if fence is _DEFAULT else fence
        emu = MavlinkVehicleEmulator(autopilot, speedup=10.0, gps_lock_s=1.0, home=HOME)
        made.append(emu)
        address = emu.start("tcp:127.0.0.1:0")
        cfg = RobotConfig(id="quad", backend="mavlink", home=HOME,
                          safety={"geofence": fence or {}, **safety},
                          mavlink=MavlinkConfig(connection=address, stream_rate_hz=5.0, **(mavlink or {})))
        b = make_backend(cfg)
        made.append(b)
        return emu, b, address

    yield make
    for obj in reversed(made):
        obj.close() if hasattr(obj, "robot_id") else obj.stop()


def _held(emu) -> list[tuple]:
    with emu._lock:
        return [(it.command, round(it.param1, 3), it.x, it.y) for it in emu.missions.fence_items]


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_the_robot_geofence_becomes_the_vehicle_fence_on_connect(vehicle, autopilot):
    emu, b, _ = vehicle(autopilot, max_altitude=35.0, mavlink={"fence": {"action": "land"}})
    b.connect(timeout_s=10)
    assert _held(emu) == FENCES[autopilot][1]
    p = emu.params
    if autopilot == "ardupilot":  # FENCE_TYPE: polygon (4, the uploaded zones) + max altitude (1)
        assert (p["FENCE_ENABLE"], p["FENCE_TYPE"], p["FENCE_ALT_MAX"], p["FENCE_ACTION"]) == (1, 5, 35, 2)
        assert p["FENCE_OPTIONS"] == 2  # two inclusion zones: their union (INCLUSION_UNION), as our gate
    else:  # GF_ACTION 5: land; GF_MAX_VER_DIST the altitude limit; no home circle asked: GF_MAX_HOR_DIST untouched
        assert (p["GF_ACTION"], p["GF_MAX_VER_DIST"], p["GF_MAX_HOR_DIST"]) == (5, 35, 0)
        # PX4's return altitudes (30 m, 10 m) are already under the 35 m fence's ceiling (31.5 m): never raised
        assert (p["RTL_RETURN_ALT"], p["RTL_DESCEND_ALT"]) == (30, 10)
    ev = [e for e in b.drain_events() if e["event"] == "fence_uploaded"]
    assert len(ev) == 1 and ev[0]["items"] == len(FENCES[autopilot][1]) and ev[0]["action"] == "land", ev


def test_ardupilot_union_bit_is_added_to_the_vehicles_options_and_restored(vehicle):
    """FENCE_OPTIONS bit 1 (INCLUSION_UNION) joins the bits the vehicle already has (here bit 0, DISABLE_MODE_CHANGE)
    and goes back with the fence; one inclusion zone leaves FENCE_OPTIONS alone."""
    emu, b, _ = vehicle("ardupilot", mavlink={"fence": {"restore_on_close": True}})
    emu.params["FENCE_OPTIONS"] = 1.0
    b.connect(timeout_s=10)
    assert emu.params["FENCE_OPTIONS"] == 3
    b.close()
    assert emu.params["FENCE_OPTIONS"] == 1
    emu, b, _ = vehicle("ardupilot", fence=FENCE_ONE)
    b.connect(timeout_s=10)
    assert emu.params["FENCE_OPTIONS"] == 0 and _held(emu) == WANT_ONE


def test_ardupilot_without_fence_options_refuses_several_inclusion_zones(vehicle):
    """An ArduPilot without FENCE_OPTIONS would intersect the two inclusion zones: refused, the fence not sent."""
    emu, b, _ = vehicle("ardupilot")
    del emu.params["FENCE_OPTIONS"]
    with pytest.raises(BackendError, match=r"no FENCE_OPTIONS parameter.*every one of the fence's 2 inclusion zones"):
        b.connect(timeout_s=10)
    assert emu.missions.fence_items == [] and emu.params["FENCE_ENABLE"] == 0


def test_px4_refuses_several_inclusion_zones_before_sending_anything(vehicle):
    """PX4 intersects inclusion zones (navigator geofence.cpp): a robot identified as PX4 on connect (autopilot auto)
    with two of them is refused before any fence item or parameter is sent."""
    emu, b, _ = vehicle("px4", fence=FENCE)
    before = dict(emu.params)
    with pytest.raises(BackendError, match=r"2 inclusion zones: PX4 requires a position inside every inclusion zone"):
        b.connect(timeout_s=10)
    assert emu.missions.fence_items == [] and emu.params == before


def test_px4s_return_altitude_is_lowered_under_the_altitude_fence(vehicle):
    """PX4's Return climbs to RTL_RETURN_ALT (30 m): at a 30 m altitude fence its own geofence counted that as a
    breach (PX4 SITL, 2026-11-23). Lowered to 27 m (10 % under); RTL_DESCEND_ALT (10 m) stays; both put back on
    close when asked."""
    emu, b, _ = vehicle("px4", max_altitude=30.0, mavlink={"fence": {"restore_on_close": True}})
    b.connect(timeout_s=10)
    p = emu.params
    assert (p["GF_MAX_VER_DIST"], p["RTL_RETURN_ALT"], p["RTL_DESCEND_ALT"]) == (30, 27, 10)
    ev = [e for e in b.drain_events() if e["event"] == "fence_uploaded"]
    assert ev and ev[0]["RTL_RETURN_ALT"] == 27, ev
    b.close()
    assert (emu.params["RTL_RETURN_ALT"], emu.params["RTL_DESCEND_ALT"]) == (30, 10)


def test_a_fence_too_low_for_px4s_return_refuses_to_fly(vehicle):
    """PX4 keeps RTL_DESCEND_ALT >= 2 m: under a 3 m altitude fence its own Return would breach it. The vehicle's
    parameters stay as they were."""
    emu, b, _ = vehicle("px4", max_altitude=3.0, min_altitude=0.5)
    before = dict(emu.params)
    with pytest.raises(BackendError, match=r"safety.max_altitude 3 m: PX4's Return mode needs at least 4 m"):
        b.connect(timeout_s=10)
    assert {n: emu.params[n] for n in ("GF_MAX_VER_DIST", "RTL_RETURN_ALT", "RTL_DESCEND_ALT")} == \
        {n: before[n] for n in ("GF_MAX_VER_DIST", "RTL_RETURN_ALT", "RTL_DESCEND_ALT")}


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_home_radius_and_hold_action(vehicle, autopilot):
    emu, b, _ = vehicle(autopilot, mavlink={"fence": {"action": "hold", "home_radius_m": 80, "max_altitude": False}},
                        max_distance=80.0)
    b.connect(timeout_s=10)
    p = emu.params
    if autopilot == "ardupilot":  # polygon (4) + circle around home (2), BRAKE or land (4)
        assert (p["FENCE_TYPE"], p["FENCE_RADIUS"], p["FENCE_ACTION"], p["FENCE_ALT_MAX"]) == (6, 80, 4, 100)
    else:
        assert (p["GF_ACTION"], p["GF_MAX_HOR_DIST"], p["GF_MAX_VER_DIST"]) == (2, 80, 0)


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_a_fence_read_back_different_refuses_to_fly(vehicle, autopilot):
    emu, b, _ = vehicle(autopilot)
    store = emu.mission_protocol.store_typed

    def corrupt(link, msg, is_int):  # the vehicle keeps the last vertex 1e-7 degrees off
        store(link, msg, is_int)
        if emu.missions.fence_items and len(emu.missions.fence_items) == len(FENCES[autopilot][1]):
            emu.missions.fence_items[3].x += 1

    emu.mission_protocol.store_typed = corrupt
    with pytest.raises(BackendError, match=r"fence read back differs.*item 3: position.*refusing to fly"):
        b.connect(timeout_s=10)


def test_a_parameter_the_vehicle_clamps_refuses_to_fly(vehicle):
    emu, b, _ = vehicle("ardupilot", max_altitude=35.0)
    store = emu.param_protocol.store
    emu.param_protocol.store = lambda name, value: store(name, min(value, 30.0) if name == "FENCE_ALT_MAX" else value)
    with pytest.raises(BackendError, match=r"FENCE_ALT_MAX set to 35, the vehicle reports 30; refusing to fly"):
        b.connect(timeout_s=10)


def test_px4_int32_parameter_sent_as_real32_is_refused_by_the_emulator(vehicle):
    """PX4 refuses a PARAM_SET typed REAL32 for an INT32 parameter ("param types mismatch"): the emulator does
    too, so the backend's bytewise INT32 GF_ACTION above is what a real PX4 takes."""
    emu, b, _ = vehicle("px4", fence=None)
    b.connect(timeout_s=10)
    with pytest.raises(BackendError, match="no PARAM_VALUE"):
        b.parameters.set("GF_ACTION", 3.0, wait_s=0.3)
    assert emu.params["GF_ACTION"] == 2
    assert b.parameters.set("GF_ACTION", 3.0, integer=True) == 3.0 and emu.params["GF_ACTION"] == 3


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_no_geofence_leaves_the_vehicle_fence_alone(vehicle, autopilot):
    emu, b, _ = vehicle(autopilot, fence=None)
    b.connect(timeout_s=10)
    assert emu.missions.fence_items == []
    assert emu.params.get("FENCE_ENABLE", 0) == 0 and emu.params.get("GF_ACTION", 2) == 2


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_restore_on_close_puts_the_previous_fence_and_parameters_back(vehicle, autopilot):
    emu, b, address = vehicle(autopilot, mavlink={"fence": {"restore_on_close": True}})
    # the operator's own fence on the vehicle before our run: one inclusion circle of 100 m
    prior = make_backend(RobotConfig(id="gcs", backend="mavlink", home=HOME, mavlink=MavlinkConfig(
        connection=address, stream_rate_hz=5.0, set_speed_limits=False)))
    prior.connect(timeout_s=10)
    from aerodaas.backends.mavlink.transfer import FENCE as FENCE_TYPE
    from aerodaas.backends.mavlink.fence import fence_items
    from aerodaas.navigation.geofence import GeofenceConfig
    prior.transfers.upload_items(FENCE_TYPE, fence_items(GeofenceConfig(circles=[{"center": _ll(0, 0), "radius": 100.0}])))
    prior.close()
    old_items = _held(emu)
    old = dict(emu.params)
    b.connect(timeout_s=10)
    assert _held(emu) == FENCES[autopilot][1]
    b.close()
    assert _held(emu) == old_items and len(old_items) == 1
    names = ["FENCE_ENABLE", "FENCE_TYPE", "FENCE_ALT_MAX", "FENCE_ACTION", "FENCE_OPTIONS"] \
        if autopilot == "ardupilot" else ["GF_ACTION", "GF_MAX_VER_DIST", "RTL_RETURN_ALT", "RTL_DESCEND_ALT"]
    assert {n: emu.params[n] for n in names} == {n: old[n] for n in names}


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_mission_upload_sends_the_plan_geofence_and_rally_points(vehicle, tmp_path, autopilot, capsys):
    """A .plan with a 25 m inclusion circle left the vehicle with 0 fence items and FENCE_ENABLE 0."""
    doc = json.loads(SQUARE.read_text())
    home = doc["mission"]["plannedHomePosition"]
    doc["geoFence"] = {"version": 2, "polygons": [
        {"version": 1, "inclusion": False, "polygon": [list(_ll(5, 5)), list(_ll(8, 5)), list(_ll(8, 8))]}],
        "circles": [{"version": 1, "inclusion": True, "circle": {"center": home[:2], "radius": 250.0}}]}
    doc["rallyPoints"] = {"version": 2, "points": [[*_ll(-10, 0), 15.0], [*_ll(0, -12), 20.0]]}
    plan = tmp_path / "fenced.plan"
    plan.write_text(json.dumps(doc))
    emu, _b, address = vehicle(autopilot, fence=None)
    assert main(["mission", "upload", str(plan), "--connection", address, "--fence-action", "hold"]) == 0, \
        capsys.readouterr().err
    held = _held(emu)
    assert [h[0] for h in held] == [5002, 5002, 5002, 5003] and held[3][1] == 250.0
    assert held[3][2:] == (round(home[0] * 1e7), round(home[1] * 1e7))
    with emu._lock:
        rally = [(it.command, it.frame, it.x, it.y, round(it.z, 2)) for it in emu.missions.rally_items]
    assert rally == [(5100, 3, round(_ll(-10, 0)[0] * 1e7), round(_ll(-10, 0)[1] * 1e7), 15.0),
                     (5100, 3, round(_ll(0, -12)[0] * 1e7), round(_ll(0, -12)[1] * 1e7), 20.0)]
    p = emu.params
    if autopilot == "ardupilot":
        assert (p["FENCE_ENABLE"], p["FENCE_TYPE"], p["FENCE_ACTION"]) == (1, 5, 4)
    else:
        assert p["GF_ACTION"] == 2 and p["GF_MAX_VER_DIST"] == 120
    assert emu.snapshot()["mission_len"] == 5 + (1 if autopilot == "ardupilot" else 0)
    out = capsys.readouterr().out
    assert "geofence of" in out and "2 rally point(s)" in out


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_mission_download_keeps_the_vehicle_fence_and_rally_points(vehicle, tmp_path, autopilot, capsys):
    from aerodaas.missionfile import load_mission

    doc = json.loads(SQUARE.read_text())
    doc["geoFence"] = {"version": 2, "polygons": [
        {"version": 1, "inclusion": False, "polygon": [list(_ll(5, 5)), list(_ll(8, 5)), list(_ll(8, 8))]}],
        "circles": [{"version": 1, "inclusion": True, "circle": {"center": [HOME.lat, HOME.lon], "radius": 250.0}}]}
    doc["rallyPoints"] = {"version": 2, "points": [[*_ll(-10, 0), 15.0]]}
    plan = tmp_path / "fenced.plan"
    plan.write_text(json.dumps(doc))
    emu, _b, address = vehicle(autopilot, fence=None)
    assert main(["mission", "upload", str(plan), "--connection", address]) == 0
    back = tmp_path / "back.plan"
    assert main(["mission", "download", "--connection", address, "--out", str(back)]) == 0
    got, want = load_mission(back), load_mission(plan)
    def zones(f):  # on the vehicle's 1e-7 degree grid
        return ([(p.inclusion, [(round(a, 7), round(b, 7)) for a, b in p.points]) for p in f.polygons],
                [(c.inclusion, round(c.center[0], 7), round(c.center[1], 7), c.radius) for c in f.circles])

    assert zones(got.geofence) == zones(want.geofence) and len(got.geofence.polygons) == 1
    assert [(round(a, 7), round(b, 7), round(z, 2)) for a, b, z in got.rally_points] == \
        [(round(a, 7), round(b, 7), round(z, 2)) for a, b, z in want.rally_points]
    wpl = tmp_path / "back.waypoints"
    assert main(["mission", "download", "--connection", address, "--out", str(wpl)]) == 0
    assert "cannot be stored in a QGC WPL file" in capsys.readouterr().err


@pytest.mark.parametrize("bad, field", [({"action": "explode"}, "fence.action"),
                                        ({"home_radius_m": -3}, "fence.home_radius_m"),
                                        ({"restore": True}, "fence.restore")])
def test_bad_fence_settings_are_refused_naming_the_field(bad, field):
    from aerodaas.config import ConfigError, parse_environment_config

    cfg = {"robots": [{"id": "quad", "backend": "mavlink", "home": {"lat": HOME.lat, "lon": HOME.lon, "alt": HOME.alt},
                       "mavlink": {"connection": "udpin:0.0.0.0:14550", "fence": bad}}]}
    with pytest.raises(ConfigError, match=rf"robots\.0\.mavlink\.{field}"):
        parse_environment_config(cfg)


def _env(autopilot: str, fence: dict, **mavlink_fence) -> dict:
    return {"robots": [{"id": "quad", "backend": "mavlink", "home": {"lat": HOME.lat, "lon": HOME.lon, "alt": HOME.alt},
                        "safety": {"geofence": fence},
                        "mavlink": {"connection": "udpin:0.0.0.0:14550", "autopilot": autopilot,
                                    "fence": mavlink_fence}}]}


def test_px4_with_several_inclusion_zones_is_refused_before_ray():
    """A robot configured as PX4 whose geofence has two inclusion zones: ConfigError naming the field, before any
    actor starts. ArduPilot (FENCE_OPTIONS), a vehicle identified on connect (auto: the backend checks then) and a
    fence flown on our gate alone (upload false) pass."""
    from aerodaas.config import ConfigError, parse_environment_config

    with pytest.raises(ConfigError, match=r"robots\.0\.safety\.geofence: robot 'quad' uploads its geofence to a px4 "
                                          r"vehicle.*2 inclusion zones"):
        parse_environment_config(_env("px4", FENCE))
    parse_environment_config(_env("px4", FENCE_ONE))
    parse_environment_config(_env("ardupilot", FENCE))
    parse_environment_config(_env("auto", FENCE))
    parse_environment_config(_env("px4", FENCE, upload=False))


def test_a_home_circle_smaller_than_max_distance_is_refused():
    """mavlink.fence.home_radius_m makes the autopilot refuse targets the gate (safety.max_distance) accepts."""
    from aerodaas.config import ConfigError, parse_environment_config

    with pytest.raises(ConfigError, match=r"robots\.0\.mavlink\.fence\.home_radius_m: 80 m is below "
                                          r"safety\.max_distance \(10000 m\)"):
        parse_environment_config(_env("ardupilot", FENCE_ONE, home_radius_m=80))
    ok = _env("ardupilot", FENCE_ONE, home_radius_m=80)
    ok["robots"][0]["safety"]["max_distance"] = 80.0
    parse_environment_config(ok)


def test_a_fence_the_vehicle_clears_after_storing_it_is_uploaded_again(vehicle):
    """ArduCopter stores a fence of fewer than 3 "vertices" (two circles), then clears it 0.1 s later when the fence
    before had more (its FENCE_TOTAL bookkeeping, AC_PolyFence_loader::update; seen on SITL). The read-back waits for
    the firmware to act, finds the fence gone, uploads it again (fence_rewritten), and it stays."""
    import threading

    two = {"circles": [{"center": _ll(-6, 0), "radius": 10.0}, {"center": _ll(6, 0), "radius": 10.0}]}
    emu, b, _ = vehicle("ardupilot", fence=two)
    store, wiped = emu.mission_protocol.store_typed, []

    def wipe_once(link, msg, is_int):
        store(link, msg, is_int)
        if not wiped and len(emu.missions.fence_items) == 2:
            wiped.append(True)

            def clear():
                with emu._lock:
                    emu.missions.fence_items.clear()

            threading.Timer(0.02, clear).start()

    emu.mission_protocol.store_typed = wipe_once
    b.connect(timeout_s=10)
    assert wiped and [h[0] for h in _held(emu)] == [5003, 5003]
    ev = [e["event"] for e in b.drain_events()]
    assert "fence_rewritten" in ev and "fence_uploaded" in ev, ev
