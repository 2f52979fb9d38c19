"""Failsafes respected (issue 26 item 6): when the autopilot enters a failsafe mode by itself (here: RTL set by a
second ground station / a pilot's switch, which the backend cannot tell from the autopilot's own), the mission
pauses, the outcome records it, and ``mavlink.on_failsafe`` decides: ``end`` leaves the vehicle to the
autopilot's RTL (never switched back to GUIDED/OFFBOARD), ``resume`` goes on with the survey. From the recording
and the emulated autopilot's own state."""
from __future__ import annotations

import threading

import pytest
from pymavlink import mavutil

from .sitl import read_recording
from .test_backends_e2e import PX4_AT_SPEED, _mavlink_variant, _run_app


def _rtl_when_navigating(address: str, flavour: str, stop: threading.Event, done: list) -> None:
    """A second ground station on the emulator's TCP port: once the vehicle has flown 3 m from home in
    GUIDED/OFFBOARD, switch it to RTL (MAV_CMD_DO_SET_MODE), once."""
    m = mavutil.mavlink_connection(address, source_system=254, source_component=191)
    m.wait_heartbeat(timeout=20)
    m.mav.request_data_stream_send(1, 1, 0, 5, 1)
    while not stop.is_set():
        msg = m.recv_match(type=["GLOBAL_POSITION_INT", "HEARTBEAT"], blocking=True, timeout=0.5)
        if msg is None or msg.get_type() != "GLOBAL_POSITION_INT":
            if msg is None:
                m.mav.heartbeat_send(6, 8, 0, 0, 0)
            continue
        if abs(msg.relative_alt) > 1000 and (abs(msg.vx) + abs(msg.vy)) > 10 and not done:
            if flavour == "px4":
                _, main, sub = mavutil.px4_map["RTL"]
                m.mav.command_long_send(1, 1, 176, 0, 1, main, sub, 0, 0, 0, 0)
            else:
                rtl = {v: k for k, v in mavutil.mode_mapping_acm.items()}["RTL"]  # custom mode 6
                m.mav.command_long_send(1, 1, 176, 0, 1, rtl, 0, 0, 0, 0, 0)
            done.append(True)
    m.close()


@pytest.mark.e2e
@pytest.mark.parametrize("flavour,action", [("ardupilot", "end"), ("px4", "end"), ("ardupilot", "resume"),
                                            ("px4", "hold")])
def test_an_autopilot_failsafe_pauses_the_mission_and_on_failsafe_decides(ray_session, run_options, tmp_path,
                                                                            flavour, action):
    emu, env_path = _mavlink_variant("farm_survey", flavour, 10.0, tmp_path, params=PX4_AT_SPEED[flavour],
                                     mavlink={"on_failsafe": action})
    stop, done = threading.Event(), []
    th = threading.Thread(target=_rtl_when_navigating, args=(emu.address, flavour, stop, done), daemon=True)
    th.start()
    try:
        res = _run_app("farm_survey", env_path, run_options, tmp_path / "farm.mcap")
        vehicle = emu.snapshot()
    finally:
        stop.set()
        th.join(5)
        emu.stop()
    rep = res.robots["quadrotor_base"]
    assert done, "the second ground station never switched the vehicle to RTL"
    rec = read_recording(tmp_path / "farm.mcap")
    ev = [m for _, m in rec["/quadrotor_base/events"]]
    fs = [e for e in ev if e["event"] == "failsafe"]
    assert len(fs) == 1 and fs[0]["mode"] == "RTL" and fs[0]["action"] == action, fs
    assert rep["failsafe"]["mode"] == "RTL" and rep["failsafe"]["action"] == action
    modes_after = [e["name"] for e in ev if e["event"] == "mode" and e["t"] >= fs[0]["t"]]
    assert not vehicle["armed"]
    if action == "end":
        assert res.outcome == "failsafe", (res.outcome, rep.get("error"))
        guided = "OFFBOARD" if flavour == "px4" else "GUIDED"
        assert guided not in modes_after, modes_after  # never switched back: the autopilot's RTL flew on
        states = [m["state"] for _, m in rec["/mission/state"]]
        assert "RETURNING" in states and states[-1] == "LANDED", states[-6:]
        assert len(rep["visited_waypoints"]) < 4
    elif action == "hold":  # paused, left to the autopilot's RTL; it landed: the flight is over, as a failsafe
        assert res.outcome == "failsafe", (res.outcome, rep.get("error"))
        assert "OFFBOARD" not in modes_after, modes_after
        states = [m["state"] for _, m in rec["/mission/state"]]
        assert "PAUSED" in states and states[-1] == "LANDED", states[-6:]
    else:
        assert res.outcome == "success", (res.outcome, rep.get("error"))
        assert "GUIDED" in modes_after and len(rep["visited_waypoints"]) == 4
