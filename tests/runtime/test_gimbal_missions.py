"""The camera gimbal pointed from an application: pitch/yaw and a region of interest, on the
simulator and on the MAVLink emulator, judged from the recording (``/<robot>/gimbal``, the frames' poses, the
events); values out of the environment's limits refused before Ray (exit 2, the field named) and at run time with
nothing sent."""
from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap

import pytest

from aerodaas.navigation.gimbal import GimbalError, roi_angles, wrap_deg
from aerodaas.recording.metrics import load_run

from tests.inputs.cli_inprocess import run_cli

LIMITS = {"pitch_min_deg": -90, "pitch_max_deg": 20, "yaw_min_deg": -120, "yaw_max_deg": 120, "rate_deg_s": 60}
ROI = (8.0, 4.0, 0.0)
POINT = (-45.0, 30.0)

#: the application: points the gimbal before the mission (carried out at take-off), then, once the drone reports
#: the gimbal there, follows a region of interest; out-of-limit calls at run time are refused with nothing sent
APP = textwrap.dedent('''
    import os, threading, time
    from aerodaas import *
    from aerodaas.navigation.gimbal import GimbalError

    env = Environment("gimbal_env.json")
    drone = env.get_robot_by_id("uav")
    scheduler = NearestNeighborScheduler(env)
    env.set_trajectory_scheduler(scheduler)
    PITCH, YAW = float(os.environ.get("GIMBAL_PITCH", "-45")), 30.0
    drone.point_gimbal(PITCH, YAW)
    refused = []

    def follow_roi_once_pointed(robot):
        def watch():
            deadline = time.monotonic() + 300
            while time.monotonic() < deadline:
                try:
                    att = robot.gimbal_attitude()
                except RuntimeError:
                    return  # the mission ended
                if att and abs(att["pitch_deg"] - PITCH) < 0.5 and abs(att["yaw_deg"] - YAW) < 0.5:
                    for bad in ((-95.0, 0.0), (0.0, float("nan"))):
                        try:
                            robot.point_gimbal(*bad)
                        except GimbalError as e:
                            refused.append(e.field)
                    robot.set_gimbal_roi({x}, {y}, {z})
                    return
                time.sleep(0.05)
        threading.Thread(target=watch, daemon=True).start()

    drone.on_mission_start(follow_roi_once_pointed)
    waypoints = [Waypoint(id="wp1", x=0, y=0, z=10, hover_duration=4),
                 Waypoint(id="wp2", x=5, y=0, z=10, hover_duration=14)]
    drone.navigate(scheduler.generate_navigation(
        AeroNavigation(NavigationType.DISTANCE_DRIVEN, waypoints, SchedulingType.ORDERED)))
    result = drone.start_mission()
''').format(x=ROI[0], y=ROI[1], z=ROI[2])


def _env(backend: str = "sim", gimbal: dict | None = LIMITS, speedup: float = 5.0) -> dict:
    robot = {"id": "uav", "backend": backend, "takeoff_altitude": 10.0,
             "limits": {"max_speed": 3.0, "max_yaw_rate": 90},
             "sensors": [{"id": "cam1", "type": "camera",
                          "properties": {"width": 160, "height": 120, "hfov_deg": 78, "fps": 4, "pitch_deg": 90}},
                         {"id": "odom", "type": "odometry", "properties": {"rate_hz": 10}}]}
    if gimbal is not None:
        robot["gimbal"] = gimbal
    return {"name": "gimbal", "robots": [robot],
            "compute": [{"id": "edge", "tier": "edge", "properties": {}}],
            "world": {"ground": {"seed": 3, "metres_per_pixel": 0.05, "size_m": 60}},
            "simulation": {"speedup": speedup, "lockstep": False}}


def _write_app(tmp_path, env: dict) -> str:
    (tmp_path / "gimbal_env.json").write_text(json.dumps(env))
    app = tmp_path / "gimbal_app.py"
    app.write_text(APP)
    return str(app)


def _odom_at(odom: list[dict], t: float) -> dict:
    return min(odom, key=lambda o: abs(o["t"] - t))


def _assert_pointed_then_followed(run: dict, limits: dict, with_frames: bool) -> None:
    """From the recording: the gimbal reached the pitch/yaw target, then the region of interest (its angles from
    the recorded pose), every recorded attitude within the limits; the commands are recorded events."""
    att, odom = run["gimbal"], run["odometry"]
    events = [e for e in run["events"] if e["event"] in ("gimbal_command", "command_rejected")]
    cmds = [e for e in events if e["event"] == "gimbal_command"]
    assert [c["command"] for c in cmds] == ["point", "roi"], events
    assert all(limits["pitch_min_deg"] - 0.01 <= a["pitch_deg"] <= limits["pitch_max_deg"] + 0.01
               and limits["yaw_min_deg"] - 0.01 <= a["yaw_deg"] <= limits["yaw_max_deg"] + 0.01 for a in att)
    t_roi = cmds[1]["t"]
    pointed = [a for a in att if a["t"] <= t_roi + 1e-6 and abs(a["pitch_deg"] - POINT[0]) < 0.5
               and abs(a["yaw_deg"] - POINT[1]) < 0.5]
    assert pointed, [(round(a["t"], 2), round(a["pitch_deg"], 1), round(a["yaw_deg"], 1)) for a in att][:60]
    # after the ROI: the last attitude (hovering at wp2, settled) looks at the ROI from the recorded pose
    last = att[-1]
    assert last["t"] > t_roi
    o = _odom_at(odom, last["t"])
    want = roi_angles(tuple(o["position"]), o["attitude"]["yaw"], ROI)
    assert abs(last["pitch_deg"] - want[0]) < 1.5 and abs(wrap_deg(last["yaw_deg"] - want[1])) < 1.5, (last, want, o)
    w, x, y, z = last["q"]
    assert abs(w * w + x * x + y * y + z * z - 1.0) < 1e-3
    if with_frames:
        poses = run["frame_poses"]
        assert poses and all(abs(p["camera_pitch"] + p["gimbal_pitch_deg"]) < 1e-6 for p in poses)
        at_point = [p for p in poses if abs(p["gimbal_pitch_deg"] - POINT[0]) < 0.5
                    and abs(p["gimbal_yaw_deg"] - POINT[1]) < 0.5]
        assert at_point, poses[:10]
        p = at_point[-1]
        vehicle_yaw = _odom_at(odom, p["t"])["attitude"]["yaw"]
        assert abs(p["camera_pitch"] - 45.0) < 0.5 and abs(wrap_deg(p["yaw"] - (vehicle_yaw - 30.0))) < 2.0


def test_an_app_points_the_simulated_gimbal_and_follows_a_roi(ray_session, run_options, tmp_path):
    from aerodaas.runtime.driver import run_file

    app = _write_app(tmp_path, _env())
    run_options.record = str(tmp_path / "g.mcap")
    res = run_file(app, run_options)[-1]
    rep = res.robots["uav"]
    assert res.outcome == "success", (rep.get("error"), rep["events"][-5:])
    run = load_run(str(tmp_path / "g.mcap"))
    _assert_pointed_then_followed(run, LIMITS, with_frames=True)
    # the two out-of-limit calls at run time were refused in the app, typed, nothing sent or recorded as sent
    refused = [e for e in rep["events"] if e["event"] == "command_rejected"]
    assert refused == []  # refused by the app's own check before reaching the drone


def test_the_same_app_on_the_mavlink_emulator(ray_session, run_options, tmp_path):
    """The autopilot emulator (ArduPilot flavour, a servo mount as ArduCopter's MNT1_TYPE 1) acknowledges
    DO_GIMBAL_MANAGER_PITCHYAW and DO_SET_ROI_LOCATION (COMMAND_INT) and streams GIMBAL_DEVICE_ATTITUDE_STATUS,
    which the drone records."""
    from aerodaas.config import parse_environment_config
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
    from aerodaas.runtime.driver import run_file

    env = _env(speedup=5.0)
    emu = MavlinkVehicleEmulator("ardupilot", robot=parse_environment_config(env).robots[0], speedup=5.0)
    addr = emu.start("tcp:127.0.0.1:0")
    env["robots"][0].update(backend="mavlink", mavlink={"connection": addr, "autopilot": "ardupilot"},
                            sensors=env["robots"][0]["sensors"][1:])
    app = _write_app(tmp_path, env)
    run_options.record = str(tmp_path / "m.mcap")
    try:
        res = run_file(app, run_options)[-1]
        seen = emu.snapshot()["commands_seen"]
    finally:
        emu.stop()
    rep = res.robots["uav"]
    assert res.outcome == "success", (rep.get("error"), rep["events"][-5:])
    assert 1000 in seen and 195 in seen, seen  # DO_GIMBAL_MANAGER_PITCHYAW, DO_SET_ROI_LOCATION reached the vehicle
    run = load_run(str(tmp_path / "m.mcap"))
    assert run["gimbal"] and all(a["source"] == "mavlink" for a in run["gimbal"])
    _assert_pointed_then_followed(run, LIMITS, with_frames=False)


def _aerodaas_run(app: str, tmp_path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", app, "--record", str(tmp_path / "x.mcap")],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          env={**__import__("os").environ, "GIMBAL_PITCH": "-120"})


def test_out_of_limit_values_are_refused_before_ray(tmp_path):
    """``point_gimbal(-120, 30)`` in the app: exit 2 naming the field and value, before Ray starts."""
    app = _write_app(tmp_path, _env())
    proc = run_cli("run", app, "--record", str(tmp_path / "x.mcap"), cwd=tmp_path,  # in-process: Ray refused
                   env={**__import__("os").environ, "GIMBAL_PITCH": "-120"})
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "pitch_deg -120.0" in proc.stderr and "uav" in proc.stderr, proc.stderr[-2000:]


@pytest.mark.parametrize("bad, field", [({"pitch_min_deg": "low"}, "pitch_min_deg"),
                                        ({"rate_deg_s": 0}, "rate_deg_s"), ({"tilt": 1}, "tilt"),
                                        ({"pitch_min_deg": 10, "pitch_max_deg": 0}, "pitch_min_deg")])
def test_a_bad_gimbal_section_is_refused_naming_the_field(bad, field):
    from aerodaas.config import ConfigError, parse_environment_config

    with pytest.raises((ConfigError, ValueError), match=field):
        parse_environment_config(_env(gimbal={**LIMITS, **bad}))


def test_no_gimbal_section_and_a_tello_with_one_are_refused_clearly():
    from aerodaas import Environment
    from aerodaas.config import ConfigError, parse_environment_config

    drone = Environment(parse_environment_config(_env(gimbal=None))).get_robot_by_id("uav")
    with pytest.raises(GimbalError, match="robot 'uav' has no gimbal"):
        drone.point_gimbal(-30.0, 0.0)
    env = _env()
    env["robots"][0].update(backend="tello", sensors=env["robots"][0]["sensors"][1:])
    with pytest.raises((ConfigError, ValueError), match="robot 'uav' has a gimbal section, but its backend 'tello'"):
        parse_environment_config(env)


def test_in_app_calls_are_checked_strictly_and_nothing_is_queued():
    from aerodaas import Environment
    from aerodaas.config import parse_environment_config

    drone = Environment(parse_environment_config(_env())).get_robot_by_id("uav")
    for args, field in (((-91.0, 0.0), "pitch_deg"), ((0.0, 121.0), "yaw_deg"), ((math.nan, 0.0), "pitch_deg"),
                        ((0.0, math.inf), "yaw_deg"), ((True, 0.0), "pitch_deg"), (("1", 0.0), "pitch_deg")):
        with pytest.raises(GimbalError) as e:
            drone.point_gimbal(*args)
        assert e.value.field == field and field in str(e.value)
    with pytest.raises(GimbalError, match="region of interest y inf"):
        drone.set_gimbal_roi(0.0, math.inf, 0.0)
    assert drone.gimbal_commands == []
    drone.point_gimbal(-90.0, 120.0)
    drone.set_gimbal_roi(1.0, 2.0)
    drone.clear_gimbal_roi()
    assert [type(c).__name__ for c in drone.gimbal_commands] == ["GimbalPoint", "GimbalRoi", "GimbalRelease"]


def test_the_drone_refuses_out_of_limit_commands_with_nothing_sent():
    """At run time the drone's safety gate checks again (a command that did not come through the app's check):
    refused, recorded as ``command_rejected``, never reaching the backend."""
    from aerodaas.actors.drone.gimbal import DroneGimbal
    from aerodaas.config import parse_environment_config
    from aerodaas.navigation.gimbal import GimbalLimits
    from aerodaas.navigation.safety import SafetyGate
    from aerodaas.protocol.gimbal import GimbalPoint, GimbalRoi

    cfg = parse_environment_config(_env()).robots[0]
    sent, events = [], []

    class Gimbal:
        def point(self, cmd):
            sent.append(cmd)

    class Backend:
        gimbal = Gimbal()

    g = DroneGimbal(Backend(), "uav", GimbalLimits(**LIMITS), SafetyGate(cfg.safety, cfg.limits, cfg.home),
                    None, lambda t: 0, lambda kind, **kw: events.append((kind, kw)))
    for cmd, field in ((GimbalPoint(-100.0, 0.0), "pitch_deg"), (GimbalPoint(0.0, math.nan), "yaw_deg"),
                       (GimbalRoi(0.0, 0.0, math.inf), "roi_z")):
        with pytest.raises(GimbalError) as e:
            g.command(cmd)
        assert e.value.field == field
    assert sent == [] and [k for k, _ in events] == ["command_rejected"] * 3
    assert g.gate.stats()["rejected"] == 3
    g.command(GimbalPoint(-10.0, 5.0))
    assert sent == [GimbalPoint(-10.0, 5.0)] and events[-1] == ("gimbal_command", {"command": "point",
                                                                                 "pitch_deg": -10.0, "yaw_deg": 5.0})
