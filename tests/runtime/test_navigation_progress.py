"""A target the vehicle does not fly towards becomes an event, and if that lasts, the waypoint ends as not reached
(an ArduCopter that silently dropped a GUIDED target outside its own fence left the drone
NAVIGATING for 330 vehicle seconds). :class:`~aerodaas.actors.drone.progress.ProgressWatch` alone, then end to end on
an emulated ArduCopter that drops the target of one waypoint as the firmware does (no COMMAND_ACK exists for
SET_POSITION_TARGET_GLOBAL_INT), judged from the recording."""
from __future__ import annotations

import pytest

from aerodaas.actors.drone.progress import ProgressWatch
from aerodaas.config import ProgressConfig


def _watch(stall=10.0, abandon=30.0, step=0.5, speed=2.0, d0=20.0):
    return ProgressWatch.for_leg(ProgressConfig(min_progress_m=step, stall_s=stall, abandon_s=abandon), 100.0, d0,
                                 speed)


def test_a_vehicle_getting_closer_is_never_stalled():
    w = _watch()
    out = [w.update(100.0 + k, 20.0 - 0.6 * k, False) for k in range(30)]  # 0.6 m/s, for 30 s
    assert out == [None] * 30


def test_no_progress_is_stalled_once_then_abandoned_at_its_time():
    w = _watch()
    verdicts = {t: w.update(100.0 + t, 20.0 + 0.01 * (t % 3), False) for t in range(0, 31)}
    assert [t for t, v in verdicts.items() if v == "stalled"] == [10]
    assert [t for t, v in verdicts.items() if v == "abandon"] == [30]
    assert w.figures(130.0, 20.0) == {"distance_m": 20.0, "closest_m": 20.0, "since_progress_s": 30.0}


def test_progress_after_a_stall_resumes_and_restarts_the_clock():
    w = _watch()
    assert [w.update(100.0 + t, 20.0, False) for t in range(11)][-1] == "stalled"
    assert w.update(112.0, 19.4, False) == "resumed"
    assert w.update(125.0, 19.4, False) == "stalled"  # 13 s after the progress at 112 s
    assert w.update(141.9, 19.3, False) is None and w.update(142.0, 19.3, False) == "abandon"


def test_inside_the_acceptance_radius_counts_as_progress():
    w = _watch(d0=0.4)
    assert all(w.update(100.0 + t, 0.25, True) is None for t in range(100))


def test_a_slow_leg_gets_a_longer_window():
    """At 0.02 m/s, 0.5 m takes 25 s: the window is 4 x that, not stall_s; abandonment never comes first."""
    w = _watch(speed=0.02)
    assert w.window_s == pytest.approx(100.0) and w.abandon_s == pytest.approx(100.0)


def test_abandon_before_stall_is_refused():
    with pytest.raises(ValueError, match="abandon_s"):
        ProgressConfig(stall_s=20.0, abandon_s=10.0)


@pytest.mark.e2e
def test_a_target_the_autopilot_drops_is_stalled_then_abandoned(ray_session, run_options, tmp_path):
    """The emulated ArduCopter drops every position target near waypoint "b" (as ArduCopter drops one its fence
    refuses) and keeps flying to the previous one: a navigation_stalled event after progress.stall_s, then
    waypoint_abandoned after abandon_s; "c" is flown after it; the outcome is incomplete and the summary says why."""
    import numpy as np

    from aerodaas import AeroNavigation, Environment, NavigationType, SchedulingType, Waypoint
    from aerodaas.model.types import GeoPoint
    from aerodaas.config import parse_environment_config
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
    from aerodaas.runtime.report import format_summary

    from tests.firmware.sitl import read_recording

    home = GeoPoint(lat=47.3977, lon=8.5456, alt=488.0)
    emu = MavlinkVehicleEmulator("ardupilot", speedup=5.0, home=home, gps_lock_s=1.0)
    apply = emu.guided.apply_target
    dropped = []

    def refuse_b(pos_enu, vel_enu, yaw_rate_dps):
        if pos_enu is not None and np.hypot(pos_enu[0] - 0.0, pos_enu[1] - 8.0) < 1.0:
            dropped.append(emu.state.t)
            return None  # ArduCopter: ModeGuided::set_destination returned false, the previous target stays
        return apply(pos_enu, vel_enu, yaw_rate_dps)

    emu.guided.apply_target = refuse_b
    addr = emu.start("tcp:127.0.0.1:0")
    try:
        robot = {"id": "d", "takeoff_altitude": 2.0, "home": home.model_dump(), "backend": "mavlink",
                 "mavlink": {"connection": addr, "autopilot": "ardupilot"},
                 "limits": {"max_speed": 2.0}, "progress": {"stall_s": 4.0, "abandon_s": 10.0},
                 "sensors": [{"id": "odom", "type": "odometry", "properties": {"rate_hz": 10}}]}
        env = Environment(parse_environment_config({"name": "progress", "robots": [robot],
                                                    "simulation": {"speedup": 5, "lockstep": False}}))
        d = env.get_robot_by_id("d")
        wps = [Waypoint(id="a", x=4, y=0, z=2), Waypoint(id="b", x=0, y=8, z=2), Waypoint(id="c", x=0, y=-4, z=2)]
        d.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, SchedulingType.ORDERED))
        run_options.record = str(tmp_path / "progress.mcap")
        res = d.start_mission(options=run_options)
    finally:
        emu.stop()
    ev = [m for _, m in read_recording(tmp_path / "progress.mcap")["/d/events"]]
    rep = res.robots["d"]
    assert dropped, "the emulator never saw a target for b"
    assert res.outcome == "incomplete", (res.outcome, rep.get("error"))
    kinds = [e["event"] for e in ev if e.get("waypoint") == "b"]
    assert kinds[:3] == ["navigate", "navigation_stalled", "waypoint_abandoned"], kinds
    nav_b = next(e for e in ev if e["event"] == "navigate" and e["waypoint"] == "b")
    stalled = next(e for e in ev if e["event"] == "navigation_stalled")
    gone = next(e for e in ev if e["event"] == "waypoint_abandoned")
    # judged on the vehicle's clock the watch read at each tick (the events' own figures; the events' stamps are
    # taken a little later, as the MAVLink link's clock runs on by itself); the upper bound only says it is bounded
    assert stalled["since_progress_s"] >= 4.0 and gone["since_progress_s"] >= 10.0 and nav_b["t"] < stalled["t"] \
        < gone["t"] and gone["elapsed_s"] < 30.0, (stalled, gone)
    assert gone["distance_m"] > 5.0 and gone["target"][:2] == [0.0, 8.0], gone
    assert [v["id"] for v in rep["visited_waypoints"]] == ["a", "c"]
    assert [h["waypoint"] for h in rep["not_reached"]] == ["b"]
    assert "not reached: b: no progress towards it for 10 s" in format_summary(res)


def test_a_vehicle_away_from_the_robots_home_is_refused_by_the_gate():
    """The gate places the fence and relative waypoints from robots[].home; a vehicle whose own home (or position)
    is farther than safety.home_tolerance_m from it flies every point that far from where the gate thinks."""
    from aerodaas.model.types import GeoPoint
    from aerodaas.config import RobotConfig
    from aerodaas.model.geo import enu_to_geodetic
    from aerodaas.navigation.safety import SafetyGate, SafetyViolation

    home = GeoPoint(lat=47.3977, lon=8.5456, alt=488.0)
    cfg = RobotConfig(id="d", home=home)
    gate = SafetyGate(cfg.safety, cfg.limits, home)
    near, far = enu_to_geodetic(3.0, 0.0, 0.0, home), enu_to_geodetic(12.0, 0.0, 0.0, home)
    gate.check_vehicle_home(GeoPoint(lat=near.lat, lon=near.lon, alt=488.0), (0.0, 0.0, 0.0))
    with pytest.raises(SafetyViolation, match=r"its home 12\.0 m from the robot's home.*home_tolerance_m 5 m"):
        gate.check_vehicle_home(GeoPoint(lat=far.lat, lon=far.lon, alt=488.0), (0.0, 0.0, 0.0))
    with pytest.raises(SafetyViolation, match=r"its position 9\.0 m from"):  # home right, but it stands elsewhere
        gate.check_vehicle_home(home, (0.0, 9.0, 0.0))


@pytest.mark.e2e
def test_a_vehicle_armed_away_from_the_robots_home_never_takes_off(ray_session, run_options, tmp_path):
    """An emulated ArduCopter standing 12 m east of robots[].home (where it arms, its home): refused after arming,
    disarmed, never in the air; the run says why."""
    from aerodaas import AeroNavigation, Environment, NavigationType, SchedulingType, Waypoint
    from aerodaas.model.types import GeoPoint
    from aerodaas.config import parse_environment_config
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
    from aerodaas.model.geo import enu_to_geodetic

    home = GeoPoint(lat=47.3977, lon=8.5456, alt=488.0)
    g = enu_to_geodetic(12.0, 0.0, 0.0, home)
    emu = MavlinkVehicleEmulator("ardupilot", speedup=5.0, home=GeoPoint(lat=g.lat, lon=g.lon, alt=488.0),
                                 gps_lock_s=1.0)
    addr = emu.start("tcp:127.0.0.1:0")
    try:
        robot = {"id": "d", "takeoff_altitude": 2.0, "home": home.model_dump(), "backend": "mavlink",
                 "mavlink": {"connection": addr, "autopilot": "ardupilot"}}
        env = Environment(parse_environment_config({"name": "home", "robots": [robot],
                                                    "simulation": {"speedup": 5, "lockstep": False}}))
        d = env.get_robot_by_id("d")
        d.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=4, y=0, z=2)],
                                  SchedulingType.ORDERED))
        run_options.record = str(tmp_path / "home.mcap")
        res = d.start_mission(options=run_options)
        snap = emu.snapshot()
    finally:
        emu.stop()
    from tests.firmware.sitl import events, odometry, read_recording

    rep = res.robots["d"]
    rec = read_recording(tmp_path / "home.mcap")
    assert res.outcome != "success"
    assert "refusing to take off: the vehicle reports its home 12.0 m from the robot's home" in str(rep.get("error")), rep
    assert [e["event"] for e in events(rec, "d") if e["event"] in ("vehicle_home_refused", "takeoff")] == \
        ["vehicle_home_refused"]
    assert not snap["armed"] and max((o["position"][2] for o in odometry(rec, "d")), default=0.0) < 0.2
