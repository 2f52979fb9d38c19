"""Plan ids (MISSION_ACK.opaque_id, MISSION_COUNT.opaque_id, MISSION_CURRENT.mission_id): read and written
through pymavlink, and the backend's start refused when the vehicle reports another mission than the one it
uploaded (the emulated PX4 gives ids as the firmware does; ArduCopter gives none). On real PX4:
``tests/firmware/test_sitl_px4.py``."""
from __future__ import annotations

import threading

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from aerodaas.backends import BackendError
from aerodaas.missionfile.plan_ids import plan_id, with_plan_id
from aerodaas.model.types import Waypoint
from tests.mavlink.emulated import position_ready, run_until, upload_as_another_station


def test_a_plan_id_crosses_a_link_in_each_message_that_carries_one():
    sender, receiver = M.MAVLink(None, 1, 1), M.MAVLink(None, 255, 190)
    for msg in (sender.mission_ack_encode(255, 190, 0, 0), sender.mission_count_encode(255, 190, 4, 0),
                sender.mission_current_encode(2, 4, 3, 1)):
        got = receiver.parse_char(with_plan_id(msg, 0xCDC4F05E).pack(sender))
        assert got.get_type() == msg.get_type() and plan_id(got) == 0xCDC4F05E
        assert {k: v for k, v in got.to_dict().items()} == msg.to_dict()  # the declared fields unchanged
        assert plan_id(receiver.parse_char(msg.pack(sender))) == 0  # none sent: none read
        assert plan_id(receiver.parse_char(with_plan_id(msg, 7).pack(sender, force_mavlink1=True))) == 0
    with pytest.raises(ValueError, match="HEARTBEAT carries no plan id"):
        with_plan_id(sender.heartbeat_encode(2, 12, 0, 0, 0), 1)
    with pytest.raises(ValueError, match="must be a uint32"):
        with_plan_id(sender.mission_ack_encode(1, 1, 0, 0), 1 << 32)


def _reports_from_before(emu, mission_id: int):
    """Start putting a MISSION_CURRENT naming ``mission_id`` on the link every 50 ms, as raw bytes (past the
    emulator's own faults) with a sequence number of its own each time (a repeated packet is dropped as a
    duplicate), like reports the vehicle sent before another station's upload that reach us late. Returns the
    callable that stops it."""
    enc = M.MAVLink(None, emu.link.system_id, emu.link.component_id)
    report = with_plan_id(enc.mission_current_encode(0, 2, M.MISSION_STATE_NOT_STARTED, 0), mission_id)
    done = threading.Event()

    def loop() -> None:
        while not done.wait(0.05):
            emu.inject(report.pack(enc))  # pack() takes the next sequence number

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()

    def stop() -> None:
        done.set()
        thread.join()
    return stop


def _armed_with_our_mission(fly):
    """An emulated PX4, our one-waypoint mission uploaded, armed on the ground: (emulator, backend, waypoints, the
    mission id the vehicle gave it)."""
    emu, b = fly("px4")
    assert run_until(b, lambda: position_ready(b), 20)
    wps = [Waypoint(id="a", x=8.0, y=0.0, z=5.0)]
    b.mission.upload(wps, takeoff_altitude=5.0, final_action="land")
    ours = [e["mission_id"] for e in b.drain_events() if e["event"] == "mission_uploaded"]
    assert ours and ours[0] != 0
    b.actions.arm()
    return emu, b, wps, ours[0]


def _refused(ours: int, theirs: int) -> str:
    return (f"the vehicle reports mission id {theirs}, not {ours}, the id it gave the mission uploaded: another "
            f"mission replaced it; not started")


def test_a_mission_another_station_replaced_after_the_upload_is_not_started(fly):
    """PX4 gives the uploaded mission an id; once the vehicle is armed another ground station uploads its own, and
    the start follows. Every MISSION_CURRENT our link delivers from then on is one the vehicle sent before that
    upload (its own reports lost for the rest of the test, old ones arriving late): they name our mission, yet the
    start asks the vehicle, raises naming both ids and sends no command (the vehicle stays on the ground, never in
    MISSION). Uploaded again, it starts and takes off (no MISSION_CURRENT needed)."""
    emu, b, wps, ours = _armed_with_our_mission(fly)
    home = b.telemetry.home
    emu.drop_next("MISSION_CURRENT", "out", count=1_000_000)
    stop_reports = _reports_from_before(emu, ours)
    try:
        theirs = upload_as_another_station(emu.address, home.lat + 1e-4, home.lon)
        assert theirs not in (0, ours)
        with pytest.raises(BackendError, match=_refused(ours, theirs)):
            b.mission.start()
    finally:
        stop_reports()
    assert not run_until(b, lambda: b.state().in_air or emu.snapshot()["mode"] == "AUTO.MISSION", 1.0)
    b.mission.upload(wps, takeoff_altitude=5.0, final_action="land")
    b.mission.start()
    assert run_until(b, lambda: b.state().in_air and b.state().position[2] > 1.0, 30), b.state().position


def test_a_late_answer_to_an_earlier_request_does_not_pass_for_the_vehicle_s(fly):
    """The mission protocol has no request ids: a MISSION_COUNT answering an earlier download, delivered late,
    names our mission and arrives just before the vehicle's answer to the start's question. The start asks twice,
    so the vehicle's own answer (the other station's mission) is still heard: refused, nothing flown."""
    emu, b, _, ours = _armed_with_our_mission(fly)
    home = b.telemetry.home
    theirs = upload_as_another_station(emu.address, home.lat + 1e-4, home.lon)
    answer = emu.handlers["MISSION_REQUEST_LIST"]
    late = []

    def late_then_answer(link, msg) -> None:  # on the emulator's thread, under its lock
        if not late:
            late.append(with_plan_id(emu.link.enc.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(), 2,
                                                                       0), ours))
            emu.link.send(late[0], link)
        answer(link, msg)

    emu.handlers["MISSION_REQUEST_LIST"] = late_then_answer
    with pytest.raises(BackendError, match=_refused(ours, theirs)):
        b.mission.start()
    assert late and emu.snapshot()["mode"] != "AUTO.MISSION"


def test_ardupilot_gives_no_plan_id_and_its_start_is_not_held_back(fly):
    """ArduCopter sends 0 in every plan id (measured on its SITL): the upload says 0 and the start goes ahead."""
    emu, b = fly("ardupilot")
    assert run_until(b, lambda: position_ready(b), 10)
    b.mission.upload([Waypoint(id="a", x=8.0, y=0.0, z=5.0)], takeoff_altitude=5.0, final_action="land")
    assert [e["mission_id"] for e in b.drain_events() if e["event"] == "mission_uploaded"] == [0]
    b.actions.arm()
    b.mission.start()
    assert run_until(b, lambda: b.state().in_air and b.state().position[2] > 1.0, 20), b.state().position


def test_a_start_the_vehicle_does_not_answer_is_refused_saying_so(fly):
    """A link that carries the upload's plan id but loses every MISSION_COUNT from then on: the start cannot confirm
    the mission and refuses after its tries, saying so rather than naming an id; nothing is flown, and the download
    it began is cancelled (MISSION_ACK OPERATION_CANCELLED: PX4 would refuse the next upload as busy until then)."""
    emu, b = fly("px4")
    assert run_until(b, lambda: position_ready(b), 10)
    b.mission.upload([Waypoint(id="a", x=8.0, y=0.0, z=5.0)], takeoff_altitude=5.0, final_action="land")
    emu.drop_next("MISSION_COUNT", "out", count=10_000)
    b.actions.arm()
    acks = []
    emu.handlers["MISSION_ACK"] = lambda link, msg: acks.append(msg.type)  # the emulated vehicle has no handler
    with pytest.raises(BackendError, match=r"start_mission: mission id check: no usable answer after \d+ tries of [\d.]+ s: "
                                           r"cannot confirm that the vehicle holds the mission uploaded \(mission id "
                                           r"\d+\); not started"):
        b.mission.start()
    assert emu.snapshot()["mode"] != "AUTO.MISSION"
    assert ("out", "MISSION_COUNT") in emu.link.faults.dropped
    assert run_until(b, lambda: acks == [M.MAV_MISSION_OPERATION_CANCELLED], 5), acks
