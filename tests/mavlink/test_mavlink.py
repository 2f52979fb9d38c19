"""The MAVLink backend against the emulated ArduPilot / PX4 vehicle (in-process, loopback TCP, faster than real
time): connect, arm, take off, fly, missions, retries, link loss, the vehicle clock. Links, wire faults, the real
PX4 log and MAVProxy are in :mod:`tests.mavlink.test_mavlink_links`."""
from __future__ import annotations

import logging
import math
import threading
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from aerodaas.backends import BackendError, CommandRefused, LinkLost
from aerodaas.backends.mavlink import CommandNotAcknowledged, MavlinkBackend
from aerodaas.backends.mavlink.params import px4_speed_limit
from aerodaas.config import MavlinkConfig, RobotConfig
from aerodaas.missionfile import load_mission
from aerodaas.model.geo import geodetic_to_enu
from aerodaas.model.types import Waypoint
from tests.conftest import DATA_DIR
from tests.mavlink.emulated import (
    AUTOPILOTS,
    CONFIG_HOME,
    PREARM_PREFIX,
    REFUSED,
    RTL_PARAMS,
    VEHICLE_HOME,
    dist,
    replace_mission_on_read,
    position_ready,
    run_until,
)


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_connect_arm_takeoff_square_velocity_land_rtl(fly, autopilot):
    # 5x, not the emulator's 10x: PX4's OFFBOARD switch needs a setpoint within COM_OF_LOSS_T (1 vehicle s) and two in
    # the last vehicle second, 0.1 wall s at 10x; a development tier at load 3-4 once stalled the stream that long at
    # all three tries of the switch. The wall-clock budgets below stay ample at 5x (takeoff 15 s = 75 vehicle s)
    emu, b = fly(autopilot, speedup=5.0, params=RTL_PARAMS[autopilot])
    assert b.link.autopilot == autopilot and b.link.vehicle_type == "MAV_TYPE_QUADROTOR"
    # HOME_POSITION replaces the configured home as ENU origin
    assert run_until(b, lambda: b.telemetry.home_received, 5)
    assert abs(b.telemetry.home.lat - VEHICLE_HOME.lat) < 1e-6 and abs(b.telemetry.home.alt - VEHICLE_HOME.alt) < 0.01
    assert dist(b.state().position, (0, 0, 0)) < 0.2
    b.actions.arm()
    assert b.state().armed and emu.snapshot()["armed"]
    b.actions.takeoff(5.0)
    assert run_until(b, lambda: abs(b.state().position[2] - 5.0) < 0.3 and b.state().in_air, 15), b.state().position
    # a 4-waypoint square flown with goto(), positions relative to the vehicle's real home
    for corner in [(8, 0, 5), (8, 8, 5), (0, 8, 5), (0, 0, 5)]:
        b.guidance.goto(corner)
        assert run_until(b, lambda: dist(b.state().position, corner) < 0.5, 20), (corner, b.state().position, b.drain_events(),
                                                                          emu.snapshot()["statustexts"])
        # the vehicle agrees with the backend (from where it armed, the EKF origin here: PX4's home moves)
        assert dist(emu.snapshot()["position_origin"], corner) < 1.0
    assert b.state().mode == ("OFFBOARD" if autopilot == "px4" else "GUIDED")
    # velocity commands are ENU: east, then north; re-sent each tick like the runtime does (from a hover)
    b.guidance.hold()
    assert run_until(b, lambda: np.linalg.norm(b.state().velocity) < 0.05, 10)
    start = b.state().position
    assert run_until(b, lambda: b.state().position[0] - start[0] > 2.5, 10, every=lambda: b.guidance.set_velocity((1.0, 0.0, 0.0)))
    assert abs(b.state().position[1] - start[1]) < 0.3 and abs(b.state().position[2] - start[2]) < 0.3
    assert b.state().velocity[0] > 0.8 and abs(b.state().velocity[1]) < 0.2 and abs(b.state().velocity[2]) < 0.2
    start = b.state().position
    assert run_until(b, lambda: b.state().position[1] - start[1] > 2.5, 10, every=lambda: b.guidance.set_velocity((0.0, 1.0, 0.0)))
    assert b.state().velocity[1] > 0.8 and abs(b.state().velocity[0]) < 0.2  # the east motion has been braked away
    b.guidance.hold()
    # land: in_air goes False, the autopilot disarms by itself
    b.guidance.land()
    assert run_until(b, lambda: not b.state().in_air and not b.state().armed, 25), (b.state().position, b.state().in_air, b.state().armed)
    assert b.state().position[2] < 0.2
    # again, then RTL from a displaced position: the autopilot flies home and lands
    b.actions.arm()
    b.actions.takeoff(4.0)
    assert run_until(b, lambda: b.state().position[2] > 3.7, 15)
    b.guidance.goto((8.0, -6.0, 4.0))
    assert run_until(b, lambda: dist(b.state().position, (8, -6, 4)) < 0.5, 20)
    assert b.guidance.return_to_launch() is True
    assert run_until(b, lambda: b.state().position[2] > 7.5, 15)  # climbs to its return altitude first
    assert run_until(b, lambda: not b.state().armed and not b.state().in_air, 40), b.state().position
    assert math.hypot(b.state().position[0], b.state().position[1]) < 1.0 and b.state().position[2] < 0.2, (
        b.state().position, emu.snapshot(), b.drain_events()[-12:])
    odo = b.telemetry.odometry()
    assert odo.robot_id == "quad" and odo.t > 10 and 0 < odo.battery_pct < 100
    names = [e["event"] for e in b.drain_events()]
    assert {"home", "armed", "disarmed", "mode"} <= set(names)
    # vehicle time runs faster than the wall clock and t follows it (at most the configured 10x; a loaded machine
    # may give the emulator less: the lower bound is load-independent)
    assert 1.0 < b.clock.ratio < 14


@pytest.mark.realtime  # PX4's setpoints at 20 Hz wall: a starved sender is its offboard-loss failsafe (it lands)
@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_goto_speed_cap(fly, autopilot):
    """goto(speed=0.5): ArduPilot through DO_CHANGE_SPEED, PX4 (which flies OFFBOARD position setpoints at its own
    limit) through a setpoint moving at 0.5 m/s; without a speed the vehicle's limit (2 m/s) applies again."""
    emu, b = fly(autopilot)
    b.actions.arm()
    b.actions.takeoff(3.0)
    assert run_until(b, lambda: b.state().position[2] > 2.8, 15)
    speeds: list = []
    sample = lambda: speeds.append(float(np.hypot(*emu.state.veh.state.velocity[:2])))  # noqa: E731 - ground truth
    t0 = b.t
    b.guidance.goto((6.0, 0.0, 3.0), speed=0.5)
    assert run_until(b, lambda: dist(b.state().position, (6, 0, 3)) < 0.3, 20, every=sample), b.state().position
    assert 10.0 < b.t - t0 < 16.0  # 6 m at 0.5 m/s, in vehicle seconds
    assert max(speeds) < 0.75  # peaks while the position loop catches up with the moving PX4 setpoint
    speeds.clear()
    b.guidance.goto((0.0, 0.0, 3.0))
    assert run_until(b, lambda: dist(b.state().position, (0, 0, 3)) < 0.3, 20, every=sample), b.state().position
    # the vehicle's own limit: ArduPilot WPNAV_SPEED 2 m/s, PX4 MPC_XY_VEL_MAX px4_speed_limit(2) = 1.75 m/s
    assert max(speeds) > (1.5 if autopilot == "ardupilot" else 0.9 * px4_speed_limit(2.0))


def test_px4_speed_limit_keeps_the_measured_overshoot_below_max_speed(fly):
    """PX4 gets MPC_XY_VEL_MAX / MPC_XY_CRUISE = max_speed - 0.25 m/s (EKF2's jolts overshoot by up to 0.24 m/s
    on SIH at any speed), never below half of max_speed; the emulated PX4 holds what was set (PARAM_VALUE)."""
    for max_speed, want in ((0.5, 0.25), (1.0, 0.75), (3.0, 2.75), (0.2, 0.1), (15.0, 14.75)):
        assert px4_speed_limit(max_speed) == pytest.approx(want), max_speed
    emu, b = fly("px4")
    limit = px4_speed_limit(b.limits.max_speed)
    assert emu.params["MPC_XY_VEL_MAX"] == pytest.approx(limit, abs=1e-4)
    assert emu.params["MPC_XY_CRUISE"] == pytest.approx(limit, abs=1e-4)


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_refused_commands_carry_result_and_status_text(fly, autopilot, caplog):
    emu, b = fly(autopilot, mavlink={"arm_timeout_s": 0.3})
    emu.set_prearm_failure("Compass not calibrated")
    with caplog.at_level(logging.INFO, logger="aerodaas.mavlink"), pytest.raises(CommandRefused) as e:
        b.actions.arm()
    # the STATUSTEXT is also a log line, at the level of its MAV_SEVERITY (CRITICAL for both autopilots' pre-arm)
    logged = [(r.levelno, r.getMessage()) for r in caplog.records if r.name == "aerodaas.mavlink"]
    assert (logging.CRITICAL, "quad: " + PREARM_PREFIX[autopilot] + "Compass not calibrated") in logged, logged
    assert e.value.result == REFUSED[autopilot]
    assert e.value.status_text == PREARM_PREFIX[autopilot] + "Compass not calibrated"
    assert REFUSED[autopilot] in str(e.value) and "Compass not calibrated" in str(e.value)
    assert not b.state().armed and not emu.snapshot()["armed"]
    # an unknown command is UNSUPPORTED
    with pytest.raises(CommandRefused) as e:
        b.commands.command_long("bogus", 31999)
    assert e.value.result == "MAV_RESULT_UNSUPPORTED"
    emu.set_prearm_failure(None)
    b.actions.arm()
    assert b.state().armed


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_arm_before_gps_fix_is_refused(fly, autopilot):
    emu, b = fly(autopilot, gps_lock_s=1e6, mavlink={"arm_timeout_s": 0.2})
    assert not b.telemetry.home_received and b.telemetry.gps_fix_type < 3
    if autopilot == "ardupilot":  # ArduCopter arms without GPS in STABILIZE; GUIDED needs it (mode change accepted)
        b.commands.set_mode("GUIDED")
    with pytest.raises(CommandRefused) as e:
        b.actions.arm()
    assert e.value.result == REFUSED[autopilot]
    assert e.value.status_text.startswith(PREARM_PREFIX[autopilot])
    # the firmware's words: ArduCopter's AHRS needs a home (a GPS fix) in GUIDED, PX4's GPS check
    assert ("waiting for home" if autopilot == "ardupilot" else "GPS fix too low") in e.value.status_text


def test_ardupilot_takeoff_refused_when_disarmed(fly):
    emu, b = fly("ardupilot")
    with pytest.raises(CommandRefused) as e:
        b.actions.takeoff(3.0)
    assert e.value.result == "MAV_RESULT_FAILED" and "not armed" in e.value.status_text


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_mission_round_trip_and_auto_flight(fly, autopilot):
    emu, b = fly(autopilot)
    assert run_until(b, lambda: b.telemetry.home_received, 5)
    square = [Waypoint(id=f"wp{i}", x=x, y=y, z=6.0, hover_duration=2.0)
              for i, (x, y) in enumerate([(10, 0), (10, 10), (0, 10)])]
    sent = b.mission.upload(square, takeoff_altitude=6.0, final_action="land")
    assert [it.command for it in sent] == [22, 16, 16, 16, 21]
    got = b.mission.download()
    assert got.items == sent
    assert emu.snapshot()["mission_len"] == len(sent) + (1 if autopilot == "ardupilot" else 0)  # ArduPilot: home
    # the report of a mission stored before (stock PX4 SIH booted with its last mission in storage sends it after a
    # new upload: that mission's last item, state NO_MISSION) and one of a finished mission: neither is progress
    last = emu.snapshot()["mission_len"] - 1
    for state in (M.MISSION_STATE_NO_MISSION, M.MISSION_STATE_COMPLETE):
        emu.inject(M.MAVLink_mission_current_message(last, last + 1, state, 2))
    b.drain_events()
    b.actions.arm()  # acknowledged after the reports (one ordered link): they were read by then
    b.mission.start()
    track: list = []
    truth: list = []  # the emulator's own position

    def sample():
        track.append(b.state().position)
        truth.append(emu.snapshot()["position_origin"])  # from where it armed (PX4's home moves in flight)

    assert run_until(b, lambda: not b.state().armed and not b.state().in_air and len(track) > 50, 60, every=sample), b.state().position
    ev = b.drain_events()
    reached = [e["item"] for e in ev if e["event"] == "mission_item_reached"]
    assert reached == [1, 2, 3, 4, 5]  # take-off, three waypoints, land: in order, each once
    current = [e["item"] for e in ev if e["event"] == "mission_current"]
    assert current == [1, 2, 3, 4, 5], current  # from the first item on, never the stored mission's last
    for wp in square:  # the vehicle went to every waypoint and held there; the backend saw it
        # PX4 resolves an item's height above home when it starts, and its home altitude moves after take-off
        # (COM_HOME_EN; up to home_alt_drift_m in the emulator), so the true height may be off by that much
        assert min(math.hypot(p[0] - wp.x, p[1] - wp.y) + max(0.0, abs(p[2] - wp.z) - emu.state.home_alt_drift_m)
                   for p in truth) < 1.0, wp.id
        assert min(math.hypot(p[0] - wp.x, p[1] - wp.y) + max(0.0, abs(p[2] - wp.z) - emu.state.home_alt_drift_m)
                   for p in track) < 2.0, wp.id
    assert max(p[2] for p in track) > 5.5 and dist(b.state().position[:2], (0, 10)) < 1.0  # landed at the last waypoint


@pytest.mark.parametrize("replaced", [1, 2])
def test_a_mission_the_vehicle_replaces_right_after_the_upload_is_sent_once_more_or_refused(fly, replaced):
    """PX4 can replace a mission it has just accepted (a mission state published meanwhile): the backend's
    read-back finds another flight and uploads once more (event ``mission_replaced``); replaced again, the upload
    raises naming what the vehicle holds, and the vehicle holds no mission to start."""
    emu, b = fly("px4")
    assert run_until(b, lambda: b.telemetry.home_received, 5)
    wps = [Waypoint(id=f"wp{i}", x=x, y=0.0, z=5.0) for i, x in enumerate((8.0, 16.0))]
    dropped = replace_mission_on_read(emu, replaced)
    if replaced == 2:
        with pytest.raises(BackendError, match="mission: count 4 sent, 0 stored; not started; the vehicle's "
                                               "mission cleared"):
            b.mission.upload(wps, takeoff_altitude=5.0, final_action="land")
        assert dropped == [4, 4] and emu.snapshot()["mission_len"] == 0
        assert not [e for e in b.drain_events() if e["event"] == "mission_uploaded"]
        return
    sent = b.mission.upload(wps, takeoff_altitude=5.0, final_action="land")
    assert dropped == [4] and [it.command for it in sent] == [22, 16, 16, 21]
    ev = b.drain_events()
    assert [(e["count"], e["stored"], e["differences"]) for e in ev if e["event"] == "mission_replaced"] == \
        [(4, 0, ["mission: count 4 sent, 0 stored"])]
    assert [e["count"] for e in ev if e["event"] == "mission_uploaded"] == [4]
    assert b.mission.download().items == sent and emu.snapshot()["mission_len"] == 4


def test_a_vehicle_holding_another_mission_after_two_uploads_is_left_with_none(fly):
    """The read-back of both uploads holds another mission (a waypoint 1 m off): the upload raises naming it, and
    clears the vehicle's mission, so that no AUTO / MISSION switch can fly what was never sent."""
    emu, b = fly("px4")
    assert run_until(b, lambda: b.telemetry.home_received, 5)
    dropped = replace_mission_on_read(emu, 2, shift_last=True)
    wps = [Waypoint(id=f"wp{i}", x=x, y=0.0, z=5.0) for i, x in enumerate((8.0, 16.0))]
    with pytest.raises(BackendError, match=r"item 4 \(MAV_CMD_NAV_LAND \(21\)\): latitude .* not started; the "
                                           r"vehicle's mission cleared"):
        b.mission.upload(wps, takeoff_altitude=5.0, final_action="land")
    assert dropped == [4, 4] and emu.snapshot()["mission_len"] == 0


def test_ardupilot_keeps_a_hold_in_whole_seconds_and_an_altitude_in_centimetres_the_mission_is_the_one_sent(fly):
    """ArduCopter stores a waypoint's hold time as whole seconds and an altitude as whole centimetres
    (``AP_Mission::mavlink_int_to_mission_cmd``; the emulator stores them so): the read-back names both with why,
    and the upload is the one sent, neither uploaded again nor refused."""
    emu, b = fly("ardupilot")
    assert run_until(b, lambda: b.telemetry.home_received, 5)
    wps = [Waypoint(id="a", x=8.0, y=0.0, z=5.005, hover_duration=2.5), Waypoint(id="b", x=16.0, y=0.0, z=5.0)]
    b.mission.upload(wps, takeoff_altitude=5.0, final_action="land")
    ev = b.drain_events()
    assert not [e for e in ev if e["event"] == "mission_replaced"], ev
    notes = [n for e in ev if e["event"] == "mission_uploaded" for n in e["fields_not_kept"]]
    assert "item 2 (MAV_CMD_NAV_WAYPOINT (16)): param1 2.5 sent, 2 stored (ArduCopter keeps this time in whole " \
           "seconds)" in notes, notes
    assert any(n.startswith("item 2 (MAV_CMD_NAV_WAYPOINT (16)): altitude 5.005 sent, 5 stored (ArduPilot keeps an "
                            "altitude in whole centimetres)") for n in notes), notes
    held = b.mission.download().items[1]
    assert held.params[0] == 2.0 and held.params[6] == pytest.approx(5.0, abs=1e-5)


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_imported_plan_round_trip(fly, autopilot):
    plan = load_mission(DATA_DIR / "missions" / "qgc_test_simple_square.plan")
    emu, b = fly(autopilot)
    sent = b.mission.upload(plan)
    assert len(sent) == len(plan.expanded_items())
    assert b.mission.download().items == sent
    for s, p in zip(sent, plan.expanded_items()):
        assert s.command == p.command and s.frame == p.frame
        if p.params[4] is not None:
            assert abs(s.params[4] - p.params[4]) < 1e-7 and abs(s.params[5] - p.params[5]) < 1e-7


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_one_lost_ack_and_lost_mission_messages_are_retried(fly, autopilot):
    """Single lost packets: the backend's bounded retries recover each, and nothing else is lost."""
    emu, b = fly(autopilot, mavlink={"command_timeout_s": 0.3, "command_retries": 2})
    assert run_until(b, lambda: position_ready(b), 10)
    b.commands.set_mode("GUIDED" if autopilot == "ardupilot" else "LOITER")
    emu.drop_next("COMMAND_ACK")  # the arm command's acknowledgement is lost: re-sent once, then acknowledged
    b.actions.arm()
    assert b.state().armed and emu.snapshot()["commands_seen"].count(400) == 2
    wps = [Waypoint(id=f"w{i}", x=x, y=5.0, z=4.0) for i, x in enumerate((0, 5, 10))]
    emu.drop_next("MISSION_COUNT", "in")  # the vehicle never hears the upload start: the backend re-sends it
    sent = b.mission.upload(wps, final_action="land")
    assert emu.snapshot()["mission_len"] == len(sent) + (1 if autopilot == "ardupilot" else 0)
    emu.drop_next("MISSION_ITEM_INT", "out")  # one answer of the download is lost: that item is requested again
    assert b.mission.download().items == sent
    assert emu.dropped == [("out", "COMMAND_ACK"), ("in", "MISSION_COUNT"), ("out", "MISSION_ITEM_INT")]
    # the two the vehicle sent and the link lost are counted by their sequence numbers (on TCP nothing else is lost)
    events: list = []
    assert run_until(b, lambda: events.extend(b.drain_events()) or any(
        e["event"] == "link_messages_lost" for e in events), 10)
    assert b.link.port.lost == 2 and b.link.port.received > 20, (b.link.port.lost, b.link.port.received)


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_every_ack_lost_but_the_heartbeat_shows_the_effect(fly, autopilot):
    """All acknowledgements of a mode change and of the arm command lost (seen with three PX4 SITL instances on a
    loaded machine: PX4 armed, no ACK arrived, the run died): the HEARTBEAT shows the mode / the armed flag, so
    the command is done (``command_ack_lost``); a command whose effect never shows still raises.

    Both tries of a command share one wall-clock budget (tries x ``command_timeout_s`` from the first send), so a
    first try that ends late (our thread starved on a loaded machine) leaves no time for the resend asserted here:
    each try gets a whole wall second, which a stall must outlast. The autopilot's auto-disarm of an idle vehicle
    (10 vehicle s, one wall second at 10x) is off, so the arm's two unanswered seconds cannot undo its effect."""
    timeout_s = 1.0
    idle_disarm_off = {"DISARM_DELAY": 0.0} if autopilot == "ardupilot" else {"COM_DISARM_PRFLT": -1.0}
    emu, b = fly(autopilot, mavlink={"command_timeout_s": timeout_s, "command_retries": 1}, params=idle_disarm_off)
    assert run_until(b, lambda: position_ready(b), 10)
    mode = "GUIDED" if autopilot == "ardupilot" else "LOITER"
    b.drain_events()
    emu.drop_next("COMMAND_ACK", count=2)
    b.commands.set_mode(mode)
    assert b.state().mode == mode
    emu.drop_next("COMMAND_ACK", count=2)
    b.actions.arm()
    assert b.state().armed and emu.snapshot()["armed"]
    events = b.drain_events()
    lost = [e["command"] for e in events if e["event"] == "command_ack_lost"]
    assert lost == [f"set mode {mode}", "arm"], lost
    # each sent twice (command_retries 1): the second send is on the record, after a whole try without an answer
    # (the stream requests of the connection may be resent too on a loaded machine: not judged here)
    resent = [(e["command"], e["attempt"], e["after"]) for e in events
              if e["event"] == "command_resent" and e["command"] in (f"set mode {mode}", "arm")]
    assert resent == [(f"set mode {mode}", 1, "no COMMAND_ACK"), ("arm", 1, "no COMMAND_ACK")], resent
    seen = emu.snapshot()["commands_seen"]  # and the vehicle heard both sends of each
    assert (seen.count(176), seen.count(400)) == (2, 2), seen  # MAV_CMD_DO_SET_MODE, MAV_CMD_COMPONENT_ARM_DISARM
    assert all(e["waited_s"] >= timeout_s for e in events if e["event"] == "command_resent")
    emu.drop_next("COMMAND_LONG", "in", count=2)  # the vehicle never hears it: no answer, no effect
    with pytest.raises(CommandNotAcknowledged, match="no COMMAND_ACK"):
        b.commands.set_mode("LAND")
    assert b.state().mode == mode


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
def test_link_loss_and_recovery(fly, autopilot):
    emu, b = fly(autopilot, speedup=5, mavlink={"heartbeat_timeout_s": 0.6})
    assert b.state().link_ok
    b.drain_events()
    emu.set_blackhole(True)
    assert run_until(b, lambda: not b.state().link_ok, 5)
    t0 = time.monotonic()
    with pytest.raises(LinkLost):
        b.actions.arm()
    with pytest.raises(LinkLost):
        b.guidance.goto((1.0, 0.0, 2.0))
    # refused at once, not after timeouts: nothing was sent to wait for, and both took less than one command's
    # tries would wait for a COMMAND_ACK (a generous bound)
    assert time.monotonic() - t0 < b.cfg.command_timeout_s * (b.cfg.command_retries + 1)
    events = b.drain_events()
    assert not [e for e in events if e["event"] in ("command_resent", "command_ack_lost")], events
    emu.set_blackhole(False)
    assert run_until(b, lambda: b.state().link_ok, 5)
    events = [e["event"] for e in events + b.drain_events()]
    assert events.index("link_lost") < events.index("link_regained")
    b.actions.arm()  # commands work again
    assert b.state().armed


def test_px4_home_moves_to_where_it_landed_and_positions_keep_their_origin(fly):
    """PX4 moves its home to where it landed once disarmed (commander HomePosition::update; seen on SIH: the
    survey's positions then jumped 9.5 m back to (0, 0) at the end of the recording): the backend reports it
    (``home_moved``) and keeps the ENU origin of the flight."""
    emu, b = fly("px4")
    events: list = []
    b.actions.arm()
    b.actions.takeoff(3.0)
    assert run_until(b, lambda: b.state().position[2] > 2.8, 15)
    b.guidance.goto((6.0, 0.0, 3.0))
    assert run_until(b, lambda: dist(b.state().position[:2], (6, 0)) < 0.3, 25), b.state().position
    b.guidance.land()
    assert run_until(b, lambda: not b.state().armed and not b.state().in_air, 40)
    landed = np.array(b.state().position[:2])
    assert dist(landed, (6, 0)) < 1.0, landed  # it descended from (6, 0), drifting on at most its last speed
    assert run_until(b, lambda: events.extend(b.drain_events()) or "home_moved" in [e["event"] for e in events], 10)
    moved = next(e for e in events if e["event"] == "home_moved")
    assert geodetic_to_enu(moved["lat"], moved["lon"], b.telemetry.home.alt, b.telemetry.home)[0] > 5.0  # the emulated PX4's new home
    # a vehicle second of samples after the home moved (not a wall-clock pause, which under load may bring none)
    t_moved = b.t
    assert run_until(b, lambda: b.t > t_moved + 1.0, 30)
    assert dist(b.state().position[:2], landed) < 0.1, (b.state().position, landed)  # still where it landed, in the flight's frame


def test_vehicle_clock_goes_on_without_a_jump_after_the_autopilot_was_stopped(monkeypatch):
    """A firmware process stopped for 6 s (SIGSTOP, as tests/firmware/sitl.py does to PX4 SITL at 5x): while silent the
    vehicle clock is extrapolated at its last rate; when time_boot_ms resumes from where it stopped, :attr:`t` goes
    on from where it got to. (It once jumped by the whole silence x the clock ratio, 28 s, leaving a gap in the
    recorded odometry: the resume event read t before the new sample's wall time was noted.)"""
    from aerodaas.backends.mavlink.clock import VehicleClock

    wall = [1000.0]
    monkeypatch.setattr(time, "monotonic", lambda: wall[0])
    class Link:  # the link's HEARTBEAT watch (clock.py LinkHealth), its socket always read empty
        link_ok = True

        def live_since(self, now: float) -> float:
            return now

    link, events = Link(), []
    clock = VehicleClock(MavlinkConfig(), lock=threading.RLock())
    clock.watch(link)
    ms = 10_000
    for _ in range(50):  # 5 vehicle seconds per wall second
        wall[0] += 0.1
        ms += 500
        events += clock.on_boot_ms(ms)
    assert 4.5 < clock.ratio < 5.5
    wall[0] += 3.0  # silent: the heartbeat watch declares the link lost (link.py periodic)
    link.link_ok = False
    clock.link_lost()
    wall[0] += 3.0
    t_silent = clock.t
    assert t_silent > 24.0 + 25.0  # 24.5 s of samples, then 6 s of silence extrapolated at 5x
    link.link_ok = True
    wall[0] += 0.1
    events += clock.on_boot_ms(ms + 500)  # the firmware goes on from its own last time stamp
    assert t_silent <= clock.t < t_silent + 1.0
    wall[0] += 0.1
    events += clock.on_boot_ms(ms + 1000)
    assert t_silent + 0.3 < clock.t < t_silent + 1.5
    assert "vehicle_clock_resumed" in events


def test_a_slow_vehicle_clock_is_no_lost_link(monkeypatch):
    """An autopilot sends HEARTBEAT at 1 Hz of its own clock: a simulator running at 0.3x real time (three PX4 SIH
    on a loaded 2-core machine) sends one every 3.3 wall seconds while its position reports go on. Not a lost link
    until its clock has run heartbeat_timeout_s past the last HEARTBEAT, or nothing timestamped arrives any more."""
    from types import SimpleNamespace as NS

    wall = [1000.0]
    monkeypatch.setattr(time, "monotonic", lambda: wall[0])
    b = MavlinkBackend(RobotConfig(id="q", backend="mavlink", home=CONFIG_HOME, mavlink=MavlinkConfig()))
    b.link.request_streams = lambda wait=True: None  # asked again when the link returns
    hb = NS(base_mode=0, custom_mode=0, type=2, autopilot=12, system_status=3, get_type=lambda: "HEARTBEAT")
    ms = 10_000
    b.clock.on_boot_ms(ms)
    b.link.on_heartbeat(hb, wall[0])
    for _ in range(33):  # 3.3 wall s at 0.3x: 0.99 vehicle s, position reports every 0.1 wall s
        wall[0] += 0.1
        ms += 30
        b.clock.on_boot_ms(ms)
        b.link.periodic(wall[0])
    assert b.state().link_ok
    for _ in range(80):  # 8 more wall s: 2.4 more vehicle s, 3.4 s past the last HEARTBEAT: missed
        wall[0] += 0.1
        ms += 30
        b.clock.on_boot_ms(ms)
        b.link.periodic(wall[0])
    assert not b.state().link_ok
    b.link.on_heartbeat(hb, wall[0])
    assert b.state().link_ok
    wall[0] += 3.1  # nothing at all arrives: lost after the wall timeout, as before
    b.link.periodic(wall[0])
    assert not b.state().link_ok


def test_a_reached_item_makes_the_next_one_current_when_mission_current_is_lost():
    """PX4 sends MISSION_ITEM_REACHED(k) and MISSION_CURRENT(k+1) from one mission result, each once (then at 1 Hz):
    with the MISSION_CURRENT lost, the next waypoint's hold starts on arrival all the same, the stale
    MISSION_CURRENT(k) that may still follow is no restart, and every item is reported reached once."""
    from types import SimpleNamespace as NS

    b = MavlinkBackend(RobotConfig(id="q", backend="mavlink", home=CONFIG_HOME, mavlink=MavlinkConfig()))
    b.link.autopilot = "px4"  # and a HEARTBEAT in PX4's AUTO.MISSION (main mode 4, sub mode 4)
    b.link.on_heartbeat(NS(base_mode=M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode=(4 << 16) | (4 << 24), type=2,
                           autopilot=M.MAV_AUTOPILOT_PX4, system_status=3, get_type=lambda: "HEARTBEAT"), 0.0)
    assert b.state().mode == "MISSION"
    b.drain_events()
    # wire 0 take-off, 1 and 2 waypoints (ENU x, y, radius), 3 land; all autocontinue
    b.mission._waypoints = {1: (0.0, 0.0, 0.5), 2: (0.0, 10.0, 0.5)}
    b.mission._next = (frozenset({0, 1, 2, 3}), 4)
    b.mission._started = b.mission._live = True  # uploaded, started, and running (state ACTIVE)
    def at(ms, east, north, up):  # a LOCAL_POSITION_NED sample (no global position): the vehicle is there
        b.telemetry.on_local_position_ned(NS(time_boot_ms=ms, x=north, y=east, z=-up, vx=0.0, vy=0.0, vz=0.0))

    at(1000, 0.0, 0.1, 1.5)
    with b._lock:
        b.mission.on_mission_current(M.MAVLink_mission_current_message(0))
        b.mission.on_mission_item_reached(NS(seq=0))  # take-off done: waypoint 1 (here) is current, its hold begins
        b.mission.on_mission_current(M.MAVLink_mission_current_message(0))  # stale, sent before the reached one
        b.mission.on_mission_item_reached(NS(seq=0))  # PX4's repeats
        at(2000, 0.0, 9.8, 1.5)
        b.mission.on_mission_item_reached(NS(seq=1))  # hold over: waypoint 2 current, and we are there
        b.mission.on_mission_current(M.MAVLink_mission_current_message(2))
        b.mission.on_mission_item_reached(NS(seq=2))
        b.mission.on_mission_current(M.MAVLink_mission_current_message(3))
    ev = [(e["event"], e.get("seq")) for e in b.drain_events()]
    assert ev == [("mission_current", 0), ("mission_item_reached", 0), ("mission_current", 1),
                  ("mission_item_reached", 1), ("mission_item_hold_done", 1), ("mission_current", 2),
                  ("mission_item_reached", 2), ("mission_item_hold_done", 2), ("mission_current", 3)], ev


def test_after_the_start_only_a_report_of_the_running_mission_is_progress():
    """Uploaded and started: a MISSION_CURRENT that arrives before the autopilot runs the new mission (a stored
    mission's last item, NO_MISSION, as a rebooted PX4 sends it; or with no state, from an older autopilot, while
    it is still in LOITER) is no progress; the first report in state ACTIVE is, and from then on every one."""
    from types import SimpleNamespace as NS

    b = MavlinkBackend(RobotConfig(id="q", backend="mavlink", home=CONFIG_HOME, mavlink=MavlinkConfig()))
    b.link.autopilot = "px4"

    def heartbeat(main_mode: int, sub_mode: int) -> None:  # PX4's custom mode: AUTO (4) .LOITER (3) / .MISSION (4)
        b.link.on_heartbeat(NS(base_mode=M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode=(main_mode << 16)
                               | (sub_mode << 24), type=2, autopilot=M.MAV_AUTOPILOT_PX4, system_status=3,
                               get_type=lambda: "HEARTBEAT"), 0.0)

    heartbeat(4, 3)
    assert b.state().mode == "LOITER"
    b.mission._uploaded = b.mission._started = True  # the state after upload() and start(): nothing reported yet
    b.drain_events()
    with b._lock:
        b.mission.on_mission_current(M.MAVLink_mission_current_message(5, 0, M.MISSION_STATE_NO_MISSION))
        b.mission.on_mission_current(M.MAVLink_mission_current_message(5, 0, 0))  # no state, not in the mission mode
        b.mission.on_mission_item_reached(NS(seq=4))
    assert [e for e in b.drain_events() if e["event"].startswith("mission_")] == []
    with b._lock:
        b.mission.on_mission_current(M.MAVLink_mission_current_message(0, 0, M.MISSION_STATE_ACTIVE))
        b.mission.on_mission_item_reached(NS(seq=0))
    heartbeat(4, 3)  # paused in LOITER: the running mission's reports stay its progress
    with b._lock:
        b.mission.on_mission_current(M.MAVLink_mission_current_message(1, 0, M.MISSION_STATE_PAUSED))
    ev = [(e["event"], e.get("seq")) for e in b.drain_events() if e["event"].startswith("mission_")]
    assert ev == [("mission_current", 0), ("mission_item_reached", 0), ("mission_current", 1)], ev


@pytest.mark.parametrize("autopilot", AUTOPILOTS)
@pytest.mark.parametrize("firmware", ["unsupported", "no_ack"])
def test_message_interval_refused_falls_back_to_request_data_stream(fly, autopilot, firmware):
    emu_kw = {"message_interval": False} if firmware == "unsupported" else {"ignore_commands": {511}}
    emu, b = fly(autopilot, mavlink={"command_timeout_s": 0.2, "command_retries": 1}, **emu_kw)
    assert any(e["event"] == "stream_fallback" for e in b.drain_events())
    # ArduPilot streams only what REQUEST_DATA_STREAM asked for; PX4 ignores it and streams its defaults
    b.actions.arm()
    b.actions.takeoff(3.0)
    assert run_until(b, lambda: b.state().position[2] > 2.7, 15), b.state().position
    assert b.telemetry.home_received and b.telemetry.gps_fix_type == 3 and b.state().in_air


@pytest.mark.realtime  # the stream's gaps in vehicle time: a starved sender stretches them (0.58 s at load 10-16)
def test_px4_offboard_setpoints_stream_above_2hz_before_and_during_offboard(fly):
    """PX4 enters OFFBOARD only with a setpoint stream of more than 2 Hz already running and needs it to go on
    (docs.px4.io, Offboard mode): every gap between the setpoints the vehicle received, from the last one before
    each switch into OFFBOARD until it leaves OFFBOARD, is at most 0.5 s of vehicle time. Run at 2x with PX4's
    default COM_OF_LOSS_T of 1 s, so a loaded machine does not stretch wall gaps into vehicle-time ones."""
    emu, b = fly("px4", speedup=2.0, params={"COM_OF_LOSS_T": 1.0})
    b.actions.arm()
    b.actions.takeoff(2.0)
    assert run_until(b, lambda: b.state().position[2] > 1.8, 15)
    b.guidance.goto((3.0, 0.0, 2.0))
    assert run_until(b, lambda: dist(b.state().position, (3, 0, 2)) < 0.5, 15)
    b.guidance.goto((3.0, 2.0, 2.0), speed=1.5)  # the moving (carrot) setpoint
    assert run_until(b, lambda: dist(b.state().position, (3, 2, 2)) < 0.5, 15)
    end = b.t + 1.0
    assert run_until(b, lambda: b.t > end, 5, every=lambda: b.guidance.set_velocity((-1.0, 0.0, 0.0)))
    b.guidance.hold()
    run_until(b, lambda: False, 0.3)
    b.guidance.land()
    assert run_until(b, lambda: not b.state().in_air, 20)
    sp, modes = list(emu.setpoint_log), list(emu.mode_log)
    spans = []  # (entered, left) OFFBOARD, vehicle seconds
    for i, (t, mode) in enumerate(modes):
        if mode == "OFFBOARD":
            spans.append((t, next(t2 for t2, m2 in modes[i + 1:] if m2 != "OFFBOARD")))
    assert spans and all(left - entered > 1.0 for entered, left in spans), modes
    for entered, left in spans:
        before = [t for t in sp if t <= entered]
        assert len([t for t in before if entered - t <= 1.0]) >= 3, "stream not running before the switch"
        times = [before[-1]] + [t for t in sp if entered < t <= left] + [left]
        gaps = np.diff(times)
        assert gaps.max() <= 0.5, (entered, left, float(gaps.max()), times[int(gaps.argmax())])
    assert not [x for x in emu.snapshot()["statustexts"] if "offboard control lost" in x]
