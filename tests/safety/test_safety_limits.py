"""One limit set: the effective limit is the minimum of every configured one, applied to waypoints,
velocity commands and take-off; RTL and the low-battery failsafe fly a path around the exclusion zones or land in
place; the physics step, speed-up, seeds and ground size have bounds checked before Ray. The end-to-end cases judge
from the recorded odometry (mcap)."""
from __future__ import annotations

import json
import math

import pytest

from aerodaas.config import ConfigError, RobotConfig, load_environment_config
from aerodaas.navigation.geofence import Geofence
from aerodaas.model.types import GeoPoint, VelocityCommand, Waypoint
from aerodaas.navigation.route import plan_path
from aerodaas.navigation.rtl import plan_return
from aerodaas.reliability.flight import PROBE_ENV
from aerodaas.navigation.safety import SafetyGate, SafetyViolation
from aerodaas.runtime.driver import run_file

HOME = {"lat": 47.3977, "lon": 8.5456, "alt": 488.0}


def _ll(e: float, n: float) -> list[float]:
    import pymap3d

    lat, lon, _ = pymap3d.enu2geodetic(e, n, 0.0, HOME["lat"], HOME["lon"], HOME["alt"])
    return [lat, lon]


def _robot(limits: dict, safety: dict) -> RobotConfig:
    return RobotConfig.model_validate({"id": "r", "home": HOME, "limits": limits, "safety": safety})


def _gate(limits: dict, safety: dict) -> SafetyGate:
    r = _robot(limits, safety)
    return SafetyGate(r.safety, r.limits, r.home)


# ------------------------------------------------------------------------------------------------- the minimum
def test_the_effective_limit_is_the_minimum_of_limits_and_safety():
    g = _gate({"max_speed": 3.0, "max_altitude": 6.0}, {"max_speed": 1.0, "max_altitude": 10.0})
    assert g.max_speed == 1.0 and g.max_alt == 6.0
    wp = g.check_waypoint(Waypoint(id="a", x=5, y=0, z=4))
    assert wp.speed == 1.0  # a waypoint without a speed is flown at the effective limit, not at limits.max_speed
    with pytest.raises(SafetyViolation, match="max_speed 1"):
        g.check_waypoint(Waypoint(id="b", x=5, y=0, z=4, speed=2.0))
    with pytest.raises(SafetyViolation, match="max_altitude"):
        g.check_waypoint(Waypoint(id="c", x=5, y=0, z=8))
    with pytest.raises(SafetyViolation, match="max_speed"):
        g.check_velocity(VelocityCommand(vx=2.0, vy=0.0, vz=0.0, duration=0.5))
    with pytest.raises(SafetyViolation, match="max_altitude"):
        g.check_takeoff(8.0)
    # the waypoint's own lower speed stays
    assert g.check_waypoint(Waypoint(id="d", x=5, y=0, z=4, speed=0.5)).speed == 0.5


def test_nothing_reaches_beyond_max_distance_from_home():
    g = _gate({}, {})
    assert g.max_dist == 10_000.0  # the documented default
    # a mistyped absolute waypoint 6,000+ km away: refused, never flown until the battery ends
    with pytest.raises(SafetyViolation, match="beyond max_distance 10000 m") as e:
        g.check_waypoint(Waypoint(id="far", x=1.0, y=60.0, z=10.0, waypoint_type="absolute"))
    assert e.value.field == "position"
    near = _ll(9_000.0, 0.0)
    assert g.check_waypoint(Waypoint(id="near", x=near[0], y=near[1], z=10.0, waypoint_type="absolute"))
    # clamping never moves a waypoint back in: a far one is refused as a geofence breach is
    c = _gate({}, {"max_distance": 50.0, "on_violation": "clamp"})
    with pytest.raises(SafetyViolation, match="beyond max_distance 50 m"):
        c.check_waypoint(Waypoint(id="out", x=40.0, y=40.0, z=5.0))
    # a velocity command is judged by where it could carry the vehicle, its stopping distance included
    with pytest.raises(SafetyViolation, match="could reach .* beyond max_distance 50 m") as e:
        c.check_velocity(VelocityCommand(vx=2.0, duration=30.0), position=(0.0, 0.0, 5.0))
    assert e.value.field == "velocity"
    c.check_velocity(VelocityCommand(vx=2.0, duration=5.0), position=(0.0, 0.0, 5.0))  # 10 m out: fine
    with pytest.raises(SafetyViolation, match="beyond max_distance"):  # already at 48 m, pushing outwards
        c.check_velocity(VelocityCommand(vx=2.0, duration=2.0), position=(48.0, 0.0, 5.0))
    # beyond the limit (pushed out by wind, or the limit was lowered): back home is allowed, farther is not
    c.check_velocity(VelocityCommand(vx=-1.0, duration=2.0), position=(51.0, 0.0, 5.0))
    with pytest.raises(SafetyViolation, match="beyond max_distance"):
        c.check_velocity(VelocityCommand(vy=1.0, duration=2.0), position=(51.0, 0.0, 5.0))
    # flying home fast earns no allowance to fly out past the limit (its stopping point lies inwards)
    fast = _gate({"max_speed": 10.0}, {"max_distance": 50.0})
    with pytest.raises(SafetyViolation, match="beyond max_distance 50 m"):
        fast.check_velocity(VelocityCommand(vx=10.0, duration=10.0), position=(49.0, 0.0, 5.0),
                            velocity=(-10.0, 0.0, 0.0))


def test_clamp_uses_the_minimum_too():
    g = _gate({"max_speed": 3.0, "max_altitude": 6.0}, {"max_speed": 1.0, "on_violation": "clamp"})
    assert g.check_waypoint(Waypoint(id="a", x=5, y=0, z=4, speed=3.0)).speed == 1.0
    assert g.check_waypoint(Waypoint(id="b", x=5, y=0, z=9)).z == pytest.approx(6.0)
    v = g.check_velocity(VelocityCommand(vx=3.0, vy=0.0, vz=0.0, duration=0.5))
    assert math.hypot(v.vx, v.vy) == pytest.approx(1.0)
    assert g.check_takeoff(9.0) == 6.0


# ------------------------------------------------------------------------------------------------- the path home
def _circle_fence(radius: float = 4.0, centre=(12.0, 0.0), square: float | None = None) -> Geofence:
    from aerodaas.navigation.geofence import GeofenceConfig

    cfg = {"circles": [{"center": _ll(*centre), "radius": radius, "inclusion": False}]}
    if square:
        s = square
        cfg["polygons"] = [{"points": [_ll(-s, -s), _ll(s, -s), _ll(s, s), _ll(-s, s)], "inclusion": True}]
    return Geofence(GeofenceConfig.model_validate(cfg), GeoPoint(**HOME))


def test_the_path_home_goes_around_an_exclusion_circle():
    fence = _circle_fence()
    assert fence.check_segment((24, 0), (0, 0)) is not None  # the straight line crosses the zone
    path = plan_path(fence, (24.0, 0.0), (0.0, 0.0), clearance=2.0)
    assert path is not None and path[0] == (24.0, 0.0) and path[-1] == (0.0, 0.0) and len(path) > 2
    # every leg (densely sampled) keeps the clearance from the circle
    for a, b in zip(path, path[1:]):
        for k in range(101):
            x, y = a[0] + (b[0] - a[0]) * k / 100, a[1] + (b[1] - a[1]) * k / 100
            assert math.hypot(x - 12.0, y) >= 4.0 + 2.0 - 1e-6
    assert fence.check_path(path) is None


def test_no_path_home_means_none():
    from aerodaas.navigation.geofence import GeofenceConfig

    # home boxed in: a ring of exclusion polygons around it, the drone outside
    ring = [{"points": [_ll(-10, -10), _ll(10, -10), _ll(10, -8), _ll(-10, -8)], "inclusion": False},
            {"points": [_ll(-10, 8), _ll(10, 8), _ll(10, 10), _ll(-10, 10)], "inclusion": False},
            {"points": [_ll(-10, -8), _ll(-8, -8), _ll(-8, 8), _ll(-10, 8)], "inclusion": False},
            {"points": [_ll(8, -8), _ll(10, -8), _ll(10, 8), _ll(8, 8)], "inclusion": False}]
    fence = Geofence(GeofenceConfig.model_validate({"polygons": ring}), GeoPoint(**HOME))
    assert plan_path(fence, (20.0, 0.0), (0.0, 0.0), clearance=1.0) is None
    r = _robot({"max_speed": 2.0}, {"geofence": {"polygons": ring}})
    path, why = plan_return(SafetyGate(r.safety, r.limits, r.home), (20.0, 0.0, 5.0), (0.0, 0.0, 0.0), 5.0)
    assert path is None and "no path home" in why


def test_plan_return_checks_every_leg_with_the_gate():
    cfg = PROBE_ENV()  # an exclusion circle of 6 m at (12, 8) inside a 60 m square
    gate = SafetyGate(cfg.safety, cfg.limits, cfg.home)
    path, why = plan_return(gate, (24.0, 16.0, 5.0), (0.0, 0.0, 0.0), 5.0)
    assert why == "" and path is not None and len(path) > 2
    assert gate.fence.check_path(path) is None and gate.rejected == 0


# ------------------------------------------------------------------------------------------------- bounds before Ray
@pytest.mark.parametrize("patch, field", [
    ({"simulation": {"physics_hz": 1.0}}, "physics_hz"),
    ({"simulation": {"physics_hz": 1e-6}}, "physics_hz"),
    ({"simulation": {"speedup": 1e-300}}, "speedup"),
    ({"simulation": {"speedup": 1e-9}}, "speedup"),
    ({"world": {"ground": {"size_m": 100000, "metres_per_pixel": 0.001}}}, "metres_per_pixel"),
    ({"world": {"ground": {"seed": -1}}}, "seed"),
    ({"robots": [{"id": "r", "home": HOME, "noise": {"seed": -1}}]}, "seed"),
    ({"robots": [{"id": "r", "home": HOME, "safety": {"max_distance": 2e5}}]}, "max_distance"),
    ({"robots": [{"id": "r", "home": HOME, "safety": {"max_distance": 0}}]}, "max_distance"),
])
def test_out_of_bounds_configs_are_refused(tmp_path, patch, field):
    doc = {"robots": [{"id": "r", "home": HOME}]}
    doc.update(patch)
    p = tmp_path / "env.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(ConfigError, match=field):
        load_environment_config(p)


@pytest.mark.parametrize("flag", ["--env", "--record"])
def test_empty_env_or_record_path_is_refused(tmp_path, flag, capsys):
    from aerodaas import cli

    app = tmp_path / "app.py"
    app.write_text("raise SystemExit(7)\n")
    assert cli.main(["run", str(app), flag, ""]) == 2
    assert f"{flag} ''" in capsys.readouterr().err


def test_speedup_below_the_bound_is_refused_before_ray(tmp_path, capsys):
    from aerodaas import cli

    app = tmp_path / "app.py"
    app.write_text("raise SystemExit(7)\n")
    assert cli.main(["run", str(app), "--speedup", "1e-300"]) == 2
    assert "--speedup" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------- end to end
APP = '''
from aerodaas import *
from aerodaas.analytics.core import NavigableAnalytics
from aerodaas.model.types import ActionCommand, AeroNavigation, NavigationType

class GoHome(NavigableAnalytics):
    """Once the drone is behind the exclusion circle, on the line from home through its centre: an app's RTL."""
    name = "gohome"
    sent = False
    def generate_navigation(self, odom, meta):
        if self.sent or odom["position"][0] < 23.0 or abs(odom["position"][1]) > 1.0:
            return None
        self.sent = True
        return AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [ActionCommand(action="rtl", reason="app")])

env = Environment(ENV)
drone = env.get_robot_by_id("r")
sched = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(sched)
if RTL:
    a = GoHome()
    a.deploy(env.get_compute_resource_by_id("edge"))
    sched.add_navigation(PriorityQueue(a.analyse(drone.get_sensor_by_id("odom").get_data_stream()), priority=1))
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, WAYPOINTS))
result = drone.start_mission()
'''


def _e2e(tmp_path, run_options, robot: dict, waypoints: str, rtl: bool):
    from aerodaas.recording.reader import read_messages

    robot.setdefault("sensors", [{"id": "odom", "type": "odometry", "properties": {"rate_hz": 10.0}}])
    robot["idle_land_s"] = 2.0
    env = tmp_path / "env.json"
    env.write_text(json.dumps({"robots": [robot], "simulation": {"speedup": 10.0}}))
    app = tmp_path / "app.py"
    app.write_text(APP.replace("ENV", repr(str(env))).replace("WAYPOINTS", waypoints).replace("RTL", str(rtl)))
    rec = tmp_path / "run.mcap"
    run_options.record = str(rec)
    res = run_file(str(app), run_options)[-1]
    msgs = [m for _, _, _, m in read_messages(rec, ["/r/odometry"])]
    return res.robots["r"], msgs


@pytest.mark.faults
@pytest.mark.e2e
def test_end_to_end_waypoints_fly_at_the_lower_safety_speed(ray_session, run_options, tmp_path):
    robot = {"id": "r", "home": HOME, "takeoff_altitude": 3.0, "limits": {"max_speed": 3.0},
             "safety": {"max_speed": 1.0}}
    rep, msgs = _e2e(tmp_path, run_options, robot, '[Waypoint(id="a", x=12, y=0, z=3)]', rtl=False)
    assert rep["outcome"] == "success", rep
    speeds = [math.hypot(m["velocity"][0], m["velocity"][1]) for m in msgs]
    assert len(speeds) > 50 and max(speeds) > 0.8  # it flew
    assert max(speeds) <= 1.05, max(speeds)


#: an inclusion fence shaped like a U upside down (ENU metres): home in the left arm, the right arm 15 m away across
#: the gap; no exclusion zone
_U_FENCE = [(-5, -5), (5, -5), (5, 20), (20, 20), (20, -5), (30, -5), (30, 30), (-5, 30)]


def test_no_path_home_inside_the_inclusion_zones_says_so():
    """With inclusion zones only, the reason spoke of exclusion zones that do not exist."""
    r = _robot({"max_speed": 2.0}, {"geofence": {"polygons": [{"points": [_ll(*p) for p in _U_FENCE]}]}})
    path, why = plan_return(SafetyGate(r.safety, r.limits, r.home), (24.0, 0.0, 3.0), (0.0, 0.0, 0.0), 3.0)
    assert path is None
    assert "stays inside the inclusion zones" in why and "24 m from home" in why and "exclusion" not in why, why


@pytest.mark.faults
@pytest.mark.e2e
def test_end_to_end_rtl_that_cannot_be_flown_is_not_a_success(ray_session, run_options, tmp_path):
    """An app's RTL with no path home inside the fence lands in place, away from home: the outcome is
    ``rtl_failed`` (it was "success", 43 m from home), the event says how far and why."""
    robot = {"id": "r", "home": HOME, "takeoff_altitude": 3.0, "limits": {"max_speed": 2.0},
             "safety": {"geofence": {"polygons": [{"points": [_ll(*p) for p in _U_FENCE]}]}}}
    rep, msgs = _e2e(tmp_path, run_options, robot,
                     '[Waypoint(id="a", x=0, y=25, z=3), Waypoint(id="b", x=25, y=25, z=3), '
                     'Waypoint(id="c", x=24, y=0, z=3)]', rtl=True)
    assert rep["outcome"] == "rtl_failed", rep
    ev = [e for e in rep["events"] if e.get("event") == "rtl_impossible"]
    assert len(ev) == 1 and 20.0 < ev[0]["distance_from_home_m"] < 28.0, rep["events"]
    assert "inclusion zones" in ev[0]["reason"] and "exclusion" not in ev[0]["reason"], ev
    end = msgs[-1]["position"]
    assert math.hypot(end[0], end[1]) > 20.0 and end[2] < 0.5, end  # landed where it was, not at home


@pytest.mark.faults
@pytest.mark.e2e
def test_end_to_end_rtl_goes_around_the_exclusion_zone(ray_session, run_options, tmp_path):
    # out along y = 8 (clear of the circle at (12, 0)), then an app's RTL: the straight line home crosses the circle
    robot = {"id": "r", "home": HOME, "takeoff_altitude": 3.0, "limits": {"max_speed": 2.0},
             "safety": {"geofence": {"circles": [{"center": _ll(12.0, 0.0), "radius": 4.0, "inclusion": False}]}}}
    rep, msgs = _e2e(tmp_path, run_options, robot,
                     '[Waypoint(id="a", x=0, y=8, z=3), Waypoint(id="b", x=24, y=8, z=3), '
                     'Waypoint(id="c", x=24, y=0, z=3), Waypoint(id="d", x=24, y=-8, z=3)]', rtl=True)
    poses = [m["position"] for m in msgs]
    behind = [p for p in poses if p[0] > 23.0 and abs(p[1]) <= 1.0]
    assert behind, "the drone never got behind the zone (the test would prove nothing)"
    ret = [e for e in rep["events"] if e.get("event") == "returning"]
    assert ret and len(ret[0]["path"]) > 1, rep["events"]  # a path of several legs, not the straight line
    closest = min(math.hypot(p[0] - 12.0, p[1]) for p in poses)
    assert closest >= 4.0, closest  # never inside the exclusion circle (the straight RTL passed 0.02 m from its centre)
    assert math.hypot(poses[-1][0], poses[-1][1]) < 1.0, poses[-1]  # and it got home


@pytest.mark.faults
@pytest.mark.e2e
def test_end_to_end_low_battery_rtl_goes_around_the_exclusion_zone(ray_session, run_options, tmp_path):
    """The low-battery failsafe returns by the same planned path as an app's RTL: the drone hovers behind an
    exclusion circle until its battery falls below low_battery_rtl_pct (energy is simulated, so where that happens
    does not depend on the machine's speed), then returns around the circle, never inside it, and gets home."""
    robot = {"id": "r", "home": HOME, "takeoff_altitude": 3.0, "limits": {"max_speed": 2.0},
             "battery": {"capacity_wh": 6.7, "hover_power_w": 180.0, "speed_power_w_per_mps": 10.0},
             "safety": {"low_battery_rtl_pct": 50.0, "critical_battery_pct": 0.0,
                        "geofence": {"circles": [{"center": _ll(12.0, 0.0), "radius": 4.0, "inclusion": False}]}}}
    rep, msgs = _e2e(tmp_path, run_options, robot,
                     '[Waypoint(id="a", x=0, y=8, z=3), Waypoint(id="b", x=24, y=8, z=3), '
                     'Waypoint(id="c", x=24, y=0, z=3, hover_duration=120)]', rtl=False)
    poses = [m["position"] for m in msgs]
    failsafe = [e for e in rep["events"] if e.get("event") == "failsafe_rtl"]
    assert failsafe, rep["events"]  # the battery failsafe, not the end of the mission, brought it home
    ret = [e for e in rep["events"] if e.get("event") == "returning"]
    assert ret and len(ret[0]["path"]) > 1, rep["events"]  # a path of several legs, not the straight line
    at = [p for p in poses if p[0] > 23.0 and abs(p[1]) <= 1.0]
    assert at, "the drone never got behind the zone (the test would prove nothing)"
    closest = min(math.hypot(p[0] - 12.0, p[1]) for p in poses)
    assert closest >= 4.0, closest
    assert math.hypot(poses[-1][0], poses[-1][1]) < 1.0, poses[-1]
