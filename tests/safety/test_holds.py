"""Holds that are held, end to end on the embedded simulator: a hold starts within the acceptance
radius and below the settle speed, counts only time within the radius, and a hold that cannot be kept ends the
waypoint as ``hold_failed`` with its figures (never reached; the mission is incomplete). Read from the recording."""
from __future__ import annotations

import pytest

from aerodaas import AeroNavigation, Environment, NavigationType, SchedulingType, Waypoint
from aerodaas.config import parse_environment_config

from tests.firmware.sitl import read_recording

pytestmark = pytest.mark.e2e


def _fly(run_options, tmp_path, noise: dict, hold: dict | None = None, backend: dict | None = None, home=None):
    robot = {"id": "d", "takeoff_altitude": 2.0, "noise": noise,
             "limits": {"max_speed": 2.0, "max_acceleration": 2.0},
             "sensors": [{"id": "odom", "type": "odometry", "properties": {"rate_hz": 10}}], **(backend or {})}
    if home is not None:
        robot["home"] = home.model_dump()
    if hold:
        robot["hold"] = hold
    env = Environment(parse_environment_config({"name": "holds", "robots": [robot],
                                                "simulation": {"speedup": 5 if backend else 20,
                                                               "lockstep": False} if backend else {"speedup": 20}}))
    d = env.get_robot_by_id("d")
    wps = [Waypoint(id="a", x=6, y=0, z=2, hover_duration=3, acceptance_radius=0.3),
           Waypoint(id="b", x=6, y=6, z=2, hover_duration=3, acceptance_radius=0.3)]
    d.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, SchedulingType.ORDERED))
    run_options.record = str(tmp_path / "holds.mcap")
    res = d.start_mission(options=run_options)
    ev = [m for _, m in read_recording(tmp_path / "holds.mcap")["/d/events"]]
    return res, ev


def test_a_hold_starts_settled_and_counts_time_within_the_radius(ray_session, run_options, tmp_path):
    res, ev = _fly(run_options, tmp_path, {})
    assert res.outcome == "success", res.robots["d"].get("error")
    reached = [e for e in ev if e["event"] == "waypoint_reached"]
    done = [e for e in ev if e["event"] == "waypoint_done"]
    assert [e["waypoint"] for e in reached] == ["a", "b"] and [e["waypoint"] for e in done] == ["a", "b"]
    for r, dn in zip(reached, done):
        assert r["speed"] <= 0.3 and r["error_m"] <= 0.3  # settled, within the radius
        assert dn["held_s"] >= 3.0 and dn["t"] - r["t"] >= 3.0 - 1e-6
    assert not [e for e in ev if e["event"] == "hold_failed"]


def test_a_hold_that_cannot_be_kept_is_hold_failed_never_reached(ray_session, run_options, tmp_path):
    """An emulated ArduCopter blown 1.5 m east by a gust whenever it has settled at waypoint "a": it flies
    back each time, but the 3 s within 0.3 m are not gathered within 1 x 3 s + 2 s; the waypoint ends as hold_failed
    with its figures (held, needed, elapsed, largest error), is not visited, and the mission is incomplete. Waypoint
    "b" (no gusts) is held and done."""
    import threading

    import numpy as np

    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
    from aerodaas.model.types import GeoPoint

    home = GeoPoint(lat=47.3977, lon=8.5456, alt=488.0)
    emu = MavlinkVehicleEmulator("ardupilot", speedup=5.0, home=home, gps_lock_s=1.0)
    addr = emu.start("tcp:127.0.0.1:0")
    stop = threading.Event()

    def gusts():
        while not stop.wait(0.1):
            s = emu.state.veh.state
            # once it has settled at "a" (where the hold starts), a gust blows it off
            if s.in_air and np.hypot(s.position[0] - 6.0, s.position[1]) < 0.3 and np.hypot(*s.velocity[:2]) < 0.3:
                s.position[0] += 1.5

    threading.Thread(target=gusts, daemon=True).start()
    try:
        res, ev = _fly(run_options, tmp_path, {}, hold={"max_time_factor": 1.0, "grace_s": 2.0},
                       backend={"backend": "mavlink", "mavlink": {"connection": addr, "autopilot": "ardupilot"}},
                       home=home)
    finally:
        stop.set()
        emu.stop()
    rep = res.robots["d"]
    assert res.outcome == "incomplete", (res.outcome, rep.get("error"))
    failed = [e for e in ev if e["event"] == "hold_failed"]
    assert [e["waypoint"] for e in failed] == ["a"], [e["event"] for e in ev]
    f = failed[0]
    assert f["held_s"] < f["needed_s"] == 3.0 and f["elapsed_s"] > 5.0 and f["max_error_m"] > 0.3, f
    assert [e["waypoint"] for e in ev if e["event"] == "waypoint_done"] == ["b"]
    assert [v["id"] for v in rep["visited_waypoints"]] == ["b"]
    assert [h["waypoint"] for h in rep["hold_failed"]] == ["a"]


def test_the_hold_radius_is_at_least_the_vehicles_position_accuracy():
    """Stock PX4 SIH reports GPS_RAW_INT h_acc 0.90 m (ArduCopter SITL 0.30 m); a 0.3 m hold there
    ended 'hold failed at wp1: 4.392 of 5 s within 0.3 m'. The radius is widened to the accuracy, unless configured
    not to; an unreported accuracy (0) leaves the waypoint's own radius."""
    from aerodaas.config.robot import HoldConfig

    assert HoldConfig().radius(0.3, 0.9) == 0.9
    assert HoldConfig().radius(0.3, 0.3) == 0.3 and HoldConfig().radius(2.0, 0.9) == 2.0
    assert HoldConfig().radius(0.3, 0.0) == 0.3
    assert HoldConfig(radius_from_vehicle=False).radius(0.3, 0.9) == 0.3


def test_a_widened_hold_is_said_in_the_summary():
    from aerodaas.runtime.report import _robot_lines

    rep = {"t": 60.0, "state": "landed", "events": [
        {"event": "waypoint_reached", "waypoint": "wp1", "radius_widened": {"from_m": 0.3, "to_m": 0.9}},
        {"event": "waypoint_reached", "waypoint": "wp2"}]}
    assert ("    holds widened to the vehicle's position accuracy (GPS_RAW_INT h_acc; hold.radius_from_vehicle): "
            "wp1 0.3 -> 0.9 m") in _robot_lines("d", rep)
