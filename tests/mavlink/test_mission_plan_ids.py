"""Plan ids (MISSION_ACK.opaque_id, MISSION_COUNT.opaque_id, MISSION_CURRENT.mission_id): read and written
through pymavlink, and the backend's start refused when the vehicle reports another mission than the one it
uploaded (the emulated PX4 gives ids as the firmware does; ArduCopter gives none). On real PX4:
``tests/firmware/test_sitl_px4.py``."""
from __future__ import annotations

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


def test_a_mission_another_station_replaced_after_the_upload_is_not_started(fly):
    """PX4 gives the uploaded mission an id; once the vehicle is armed another ground station uploads its own, and
    the start follows at once: our link's last MISSION_CURRENT still reports our id (PX4 announces the new one only
    on the uploading link, then at 1 Hz; in real time here), so only the next report tells. The start raises naming
    both ids and sends nothing (the vehicle stays on the ground, never in MISSION); uploaded again, it starts and
    takes off."""
    emu, b = fly("px4", speedup=1.0)
    assert run_until(b, lambda: position_ready(b), 20)
    wps = [Waypoint(id="a", x=8.0, y=0.0, z=5.0)]
    b.mission.upload(wps, takeoff_altitude=5.0, final_action="land")
    ours = [e["mission_id"] for e in b.drain_events() if e["event"] == "mission_uploaded"]
    assert ours and ours[0] != 0
    b.actions.arm()
    home = b.telemetry.home
    theirs = upload_as_another_station(emu.address, home.lat + 1e-4, home.lon)
    assert theirs not in (0, ours[0])
    with pytest.raises(BackendError, match=f"the vehicle reports mission id {theirs}, not {ours[0]}, the id it gave "
                                           f"the mission uploaded: another mission replaced it; not started"):
        b.mission.start()
    assert not run_until(b, lambda: b.state().in_air or emu.snapshot()["mode"] == "AUTO.MISSION", 1.0)
    b.mission.upload(wps, takeoff_altitude=5.0, final_action="land")
    b.mission.start()
    assert run_until(b, lambda: b.state().in_air and b.state().position[2] > 1.0, 30), b.state().position


def test_ardupilot_gives_no_plan_id_and_its_start_is_not_held_back(fly):
    """ArduCopter sends 0 in every plan id (measured on its SITL): the upload says 0 and the start goes ahead."""
    emu, b = fly("ardupilot")
    assert run_until(b, lambda: position_ready(b), 10)
    b.mission.upload([Waypoint(id="a", x=8.0, y=0.0, z=5.0)], takeoff_altitude=5.0, final_action="land")
    assert [e["mission_id"] for e in b.drain_events() if e["event"] == "mission_uploaded"] == [0]
    b.actions.arm()
    b.mission.start()
    assert run_until(b, lambda: b.state().in_air and b.state().position[2] > 1.0, 20), b.state().position


def test_a_start_no_mission_current_confirms_is_refused_saying_so(fly):
    """A link that carries the upload's plan id but no MISSION_CURRENT (a router filtering it): the first start
    cannot confirm the mission and refuses after its wait, saying that none came rather than naming an id."""
    emu, b = fly("px4")
    assert run_until(b, lambda: position_ready(b), 10)
    b.mission.upload([Waypoint(id="a", x=8.0, y=0.0, z=5.0)], takeoff_altitude=5.0, final_action="land")
    emu.drop_next("MISSION_CURRENT", "out", count=10_000)
    b.actions.arm()
    with pytest.raises(BackendError, match=r"start_mission: no MISSION_CURRENT from the vehicle within 3 s to confirm "
                                           r"that it holds the mission uploaded \(mission id \d+\); not started"):
        b.mission.start()
    assert emu.snapshot()["mode"] != "AUTO.MISSION"
