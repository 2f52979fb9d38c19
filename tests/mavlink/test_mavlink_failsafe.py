"""Failsafes respected: when the autopilot enters a failsafe mode by itself (here: RTL set by a
second ground station / a pilot's switch, which the backend cannot tell from the autopilot's own), the mission
pauses, the outcome records it, and ``mavlink.on_failsafe`` decides: ``end`` leaves the vehicle to the
autopilot's RTL (never switched back to GUIDED/OFFBOARD), ``resume`` goes on with the survey. From the recording
and the emulated autopilot's own state."""
from __future__ import annotations

import threading
import time

import pytest
from pymavlink import mavutil

from tests.firmware.sitl import read_recording
from tests.runtime.test_backends_e2e import PX4_AT_SPEED, _mavlink_variant, _run_app


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


#: The autopilot's RTL climbs to 3 m, not its default return altitude (ArduCopter RTL_ALT 15 m, PX4 RTL_RETURN_ALT
#: 30 m): nothing below depends on the height, and climbing there and descending at the landing speed
#: (0.5 / 0.7 m/s) was most of a failsafe test's flight.
LOW_RTL = {"ardupilot": {"RTL_ALT": 300.0}, "px4": {"RTL_RETURN_ALT": 3.0}}


@pytest.mark.e2e
@pytest.mark.parametrize("flavour,action", [("ardupilot", "end"), ("px4", "end"), ("ardupilot", "resume"),
                                            ("px4", "hold")])
def test_an_autopilot_failsafe_pauses_the_mission_and_on_failsafe_decides(ray_session, run_options, tmp_path,
                                                                            flavour, action):
    emu, env_path = _mavlink_variant("farm_survey", flavour, 10.0, tmp_path,
                                     params={**PX4_AT_SPEED[flavour], **LOW_RTL[flavour]},
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


def test_px4_offboard_loss_failsafe_is_not_undone_when_our_process_resumes(fly):
    """Our I/O stalls (as under SIGSTOP or a loaded machine) for 3x COM_OF_LOSS_T of vehicle time in OFFBOARD
    flight: the emulated PX4 runs its offboard-loss failsafe (Return) and, like the real one, would fly OFFBOARD
    again as soon as setpoints come back (PX4 SITL did: RTL, then OFFBOARD 1 s later, CI run of 2026-11-23). When
    the stall ends, the backend reads what the vehicle said meanwhile before sending anything, so the firmware never
    goes back to OFFBOARD; the failsafe is reported; a goto before the caller has the failsafe event is withheld;
    after it, a goto (``on_failsafe: resume``) switches back on purpose."""
    from tests.mavlink.emulated import dist, run_until

    emu, b = fly("px4", speedup=2.0, params={"COM_OF_LOSS_T": 1.0})
    assert any(e["event"] == "offboard_loss_timeout" and e["seconds"] == 1.0 for e in b.drain_events())
    b.actions.arm()
    b.actions.takeoff(2.0)
    assert run_until(b, lambda: b.state().position[2] > 1.8, 15)
    b.guidance.goto((0.0, 30.0, 2.0))
    assert run_until(b, lambda: b.state().mode == "OFFBOARD" and b.state().position[1] > 1.0, 15), (b.state().mode, b.state().position)
    b.drain_events()
    gate, port = threading.Event(), b.link.port  # stall the backend's receive path, as a stopped process would
    real = port.recv_msg

    def stalled():
        gate.wait()
        return real()

    port.recv_msg = stalled
    end = time.monotonic() + 20
    while emu.snapshot()["mode"] != "AUTO.RTL" and time.monotonic() < end:
        time.sleep(0.02)
    assert emu.snapshot()["mode"] == "AUTO.RTL", emu.snapshot()["mode"]
    time.sleep(0.3)
    port.recv_msg = real
    gate.set()
    assert run_until(b, lambda: b.link.failsafe is not None, 10), b.state().mode
    run_until(b, lambda: False, 1.5)
    modes = [m for _, m in emu.mode_log]
    left = len(modes) - 1 - modes[::-1].index("AUTO.RTL")
    assert "OFFBOARD" not in modes[left:], emu.mode_log
    assert b.link.failsafe["mode"] == "RTL", b.link.failsafe
    # the caller has not taken the failsafe event yet: a goto now is withheld, nothing reaches the vehicle
    b.guidance.goto((0.0, 0.0, 2.0))
    run_until(b, lambda: False, 0.5)
    assert emu.snapshot()["mode"] == "AUTO.RTL", emu.mode_log
    events = [e["event"] for e in b.drain_events()]
    assert "autopilot_failsafe" in events and "command_withheld" in events, events
    # with the event in hand, the caller may take the vehicle back (mavlink.on_failsafe: resume)
    b.guidance.goto((0.0, 0.0, 2.0))
    assert run_until(b, lambda: emu.snapshot()["mode"] == "OFFBOARD", 10), emu.mode_log
    assert run_until(b, lambda: dist(b.state().position, (0, 0, 2)) < 0.6, 40), b.state().position
    b.close(safe_end=False)  # not the fixture's landing in 2x vehicle time: this test is over


def test_px4_a_short_stall_of_ours_keeps_the_stream_and_offboard(fly):
    """The negative case: our receive path stalls for 2 of PX4's 3 s COM_OF_LOSS_T (1x): past half the timeout, so
    the backend waits for a sample received after the stall, finds the vehicle's clock short of the timeout and
    goes on streaming; PX4 never left OFFBOARD, no ``offboard_stream_stalled``, no withheld command."""
    from tests.mavlink.emulated import run_until

    emu, b = fly("px4", speedup=1.0, params={"COM_OF_LOSS_T": 3.0})
    b.actions.arm()
    b.actions.takeoff(2.0)
    assert run_until(b, lambda: b.state().position[2] > 1.8, 30)
    b.guidance.goto((0.0, 30.0, 2.0))
    assert run_until(b, lambda: b.state().mode == "OFFBOARD", 15), b.state().mode
    b.drain_events()
    gate, port = threading.Event(), b.link.port
    real = port.recv_msg

    def stalled():
        gate.wait()
        return real()

    port.recv_msg = stalled
    time.sleep(2.0)
    port.recv_msg = real
    gate.set()
    n0 = len(emu.setpoint_log)
    run_until(b, lambda: False, 2.0)
    assert len(emu.setpoint_log) > n0 + 5, (n0, len(emu.setpoint_log))
    assert [m for _, m in emu.mode_log][-1] == "OFFBOARD", emu.mode_log
    events = [e["event"] for e in b.drain_events()]
    assert not {"offboard_stream_stalled", "command_withheld", "autopilot_failsafe"} & set(events), events
    b.close(safe_end=False)  # not the fixture's landing in real time: this test is over
