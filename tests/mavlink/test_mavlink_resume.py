"""A resume the vehicle refuses: the farm survey flown as an autopilot mission on the emulated PX4, paused through the
application (``pause_mission`` / ``resume_mission``; the HITL API is refused beside an autopilot mission), its
mission replaced meanwhile by another ground station's upload. The resume's start is refused (the
vehicle reports another mission id than it gave ours), so the drone stays PAUSED, hovering, with the refusal
recorded, and never flies on as NAVIGATING; the other station then lands the vehicle, which ends the flight. From the
recording and the emulated autopilot's own state."""
from __future__ import annotations

import threading
import time

import pytest
from pymavlink import mavutil

from aerodaas.recording.metrics import load_run
from tests.mavlink.emulated import upload_as_another_station
from tests.runtime.test_backends_e2e import _mavlink_variant

def _until(cond, what: str, th: threading.Thread, out: dict, timeout_s: float = 120.0) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        assert th.is_alive() and time.monotonic() < end, (what, out)
        time.sleep(0.05)


def _land_as_another_station(address: str) -> None:
    """Another ground station switches the vehicle to PX4 AUTO.LAND (MAV_CMD_DO_SET_MODE)."""
    m = mavutil.mavlink_connection(address, source_system=254, source_component=191)
    try:
        m.wait_heartbeat(timeout=10)
        _, main, sub = mavutil.px4_map["LAND"]
        m.mav.command_long_send(1, 1, 176, 0, 1, main, sub, 0, 0, 0, 0)
        m.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
    finally:
        m.close()


#: the farm survey's first two corners, flown as an autopilot mission; a thread of the app pauses and resumes the
#: drone when the test says so (files in DIR: ``pause`` -> ``paused``, ``resume`` -> ``resumed``)
APP = """import pathlib, threading, time
from aerodaas import *
env = Environment("farm_survey.json")
drone = env.get_robot_by_id("quadrotor_base")
d = pathlib.Path(DIR)

def when(name):
    while not (d / name).exists():
        time.sleep(0.02)

def pause_then_resume(robot):
    def go():
        when("pause")
        robot.pause_mission()
        (d / "paused").touch()
        when("resume")
        robot.resume_mission()
        (d / "resumed").touch()
    threading.Thread(target=go, daemon=True).start()

drone.on_mission_start(pause_then_resume)
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="wp1", x=0, y=10, z=1.5, hover_duration=5),
                                                              Waypoint(id="wp2", x=10, y=10, z=1.5)],
                              SchedulingType.ORDERED))
drone.start_mission()
"""


def _start_app(run_options, tmp_path) -> tuple:
    """:data:`APP` on the emulated PX4 (10x, the farm survey's robot flying autopilot missions, recorded to
    ``farm.mcap``), run on a thread: (emulator, thread, ``out`` with the run's ``res`` or its ``error``)."""
    from aerodaas.runtime.driver import run_file

    emu, env_path = _mavlink_variant("farm_survey", "px4", 10.0, tmp_path, mavlink={"use_autopilot_mission": True},
                                     params={"COM_OF_LOSS_T": 5.0}, without=("cam1",))
    app = tmp_path / "pause_app.py"
    app.write_text(APP.replace("DIR", repr(str(tmp_path))))
    run_options.env_path, run_options.record = str(env_path), str(tmp_path / "farm.mcap")
    out: dict = {}

    def run() -> None:
        try:
            out["res"] = run_file(str(app), run_options)[-1]
        except BaseException as e:  # noqa: BLE001 - said in the assertions
            out["error"] = repr(e)

    th = threading.Thread(target=run, daemon=True)
    th.start()
    return emu, th, out


def _ended(emu, th: threading.Thread, out: dict, what: str) -> dict:
    """Wait for the run's end (failing with ``what`` after 120 s); the emulated vehicle's own state then."""
    th.join(timeout=120)
    assert not th.is_alive(), what
    assert "res" in out, out
    return emu.snapshot()


@pytest.mark.e2e
def test_a_resume_the_vehicle_refuses_keeps_the_drone_paused(ray_session, run_options, tmp_path):
    emu, th, out = _start_app(run_options, tmp_path)
    try:
        # past the take-off item: on the way to, or holding at, wp1
        _until(lambda: emu.snapshot()["mission_seq"] >= 1 and emu.snapshot()["mode"] == "AUTO.MISSION",
               "never flew the mission", th, out)
        time.sleep(0.3)
        (tmp_path / "pause").touch()
        _until(lambda: (tmp_path / "paused").exists(), "never paused", th, out)
        _until(lambda: emu.snapshot()["mode"] == "AUTO.LOITER", "the pause never reached the vehicle", th, out, 10.0)
        home = emu.state.home or emu.state.origin
        upload_as_another_station(emu.address, home.lat + 1e-4, home.lon)
        (tmp_path / "resume").touch()
        _until(lambda: (tmp_path / "resumed").exists(), "never asked to resume", th, out)
        time.sleep(1.0)  # ten vehicle seconds at 10x: a resumed mission would be flying by now
        assert emu.snapshot()["mode"] != "AUTO.MISSION", list(emu.mode_log)
        _land_as_another_station(emu.address)
        vehicle = _ended(emu, th, out, "the run did not end after the vehicle landed")
    finally:
        emu.stop()
    assert out["res"].outcome != "success" and not vehicle["armed"] and not vehicle["in_air"], out["res"].outcome
    run = load_run(str(tmp_path / "farm.mcap"))
    refused = [e for e in run["events"] if e["event"] == "backend_error"
               and "another mission replaced it; not started" in e["error"]]
    assert len(refused) == 1, [e for e in run["events"] if e["event"] == "backend_error"]
    assert not [e for e in run["events"] if e["event"] == "resumed"]
    states = [m["state"] for m in run["states"]]
    assert "PAUSED" in states and "NAVIGATING" not in states[states.index("PAUSED"):], states[-8:]


@pytest.mark.e2e
def test_a_pause_during_the_autopilot_missions_take_off_holds_the_vehicle_and_the_resume_flies_on(
        ray_session, run_options, tmp_path):
    """Paused the moment the autopilot switches to its mission (taking off, often before its landed state says
    airborne): the vehicle goes to its hold mode (the drone's hold used to only stop our targets while the landed
    state said on the ground, and the mission flew on under PAUSED: 1 of 3 runs of this test); resumed, it flies
    the mission to its end (both waypoints, landed)."""
    emu, th, out = _start_app(run_options, tmp_path)
    try:
        _until(lambda: emu.snapshot()["mode"] == "AUTO.MISSION", "never started the mission", th, out)
        (tmp_path / "pause").touch()
        _until(lambda: emu.snapshot()["mode"] == "AUTO.LOITER", "the pause never reached the vehicle", th, out, 10.0)
        (tmp_path / "resume").touch()
        vehicle = _ended(emu, th, out, "the run did not end")
    finally:
        emu.stop()
    rep = out["res"].robots["quadrotor_base"]
    assert out["res"].outcome == "success", (rep.get("error"), rep["events"][-5:])
    assert [v["id"] for v in rep["visited_waypoints"]] == ["wp1", "wp2"] and not vehicle["armed"]
    run = load_run(str(tmp_path / "farm.mcap"))
    assert [e["event"] for e in run["events"] if e["event"] in ("paused", "resumed")] == ["paused", "resumed"]
