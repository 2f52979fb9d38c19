"""``aerodaas mission upload`` / ``download`` against the emulated ArduPilot and PX4 vehicles (loopback TCP)."""
from __future__ import annotations

import socket
from pathlib import Path

import pytest

from aerodaas.cli import main
from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
from aerodaas.missionfile import load_mission
from aerodaas.model.types import GeoPoint
from tests.conftest import DATA_DIR
from tests.mavlink.emulated import replace_mission_on_arm, replace_mission_on_read

SQUARE = DATA_DIR / "missions" / "qgc_test_simple_square.plan"  # take-off + 4-waypoint square


@pytest.fixture
def vehicle():
    made: list = []

    def make(autopilot: str, **kw) -> tuple[MavlinkVehicleEmulator, str]:
        emu = MavlinkVehicleEmulator(autopilot, speedup=10.0, gps_lock_s=1.0,
                                     home=GeoPoint(lat=47.397742, lon=8.545594, alt=488.0), **kw)
        made.append(emu)
        return emu, emu.start("tcp:127.0.0.1:0")

    yield make
    for emu in made:
        emu.stop()


def _positions(path):
    return [(it.command, it.params[4], it.params[5], it.params[6]) for it in load_mission(path).expanded_items()]


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
@pytest.mark.parametrize("out_name", ["back.plan", "back.waypoints"])
def test_upload_then_download_round_trips(vehicle, tmp_path, autopilot, out_name):
    emu, address = vehicle(autopilot)
    assert main(["mission", "upload", str(SQUARE), "--connection", address, "--autopilot", autopilot]) == 0
    assert emu.snapshot()["mission_len"] == 5 + (1 if autopilot == "ardupilot" else 0)  # ArduPilot: home at 0
    out = tmp_path / out_name
    assert main(["mission", "download", "--connection", address, "--out", str(out)]) == 0
    want, got = _positions(SQUARE), _positions(out)
    assert len(got) == len(want) == 5
    for (c0, lat0, lon0, z0), (c1, lat1, lon1, z1) in zip(want, got):
        assert c0 == c1 and abs(lat0 - lat1) < 1e-6 and abs(lon0 - lon1) < 1e-6 and abs(z0 - z1) < 0.01
    home = load_mission(out).home
    assert abs(home.lat - 47.397742) < 1e-6 and abs(home.alt - 488.0) < 0.01


def test_upload_start_arms_and_flies(vehicle):
    emu, address = vehicle("px4")
    assert main(["mission", "upload", str(SQUARE), "--connection", address, "--start"]) == 0
    snap = emu.snapshot()
    assert snap["armed"] and snap["mode"] in ("AUTO.MISSION", "AUTO.TAKEOFF"), snap["mode"]


def test_errors_name_the_file_item_or_connection_and_send_nothing(vehicle, tmp_path, capsys):
    emu, address = vehicle("ardupilot")
    assert main(["mission", "upload", str(tmp_path / "nope.plan"), "--connection", address]) == 2
    assert "nope.plan" in capsys.readouterr().err
    bad = tmp_path / "bad.waypoints"  # MAV_CMD_CONDITION_DELAY (112): not something AeroDaaS can fly
    bad.write_text("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488\t1\n"
                   "1\t0\t3\t22\t0\t0\t0\t0\t47.397742\t8.545594\t10\t1\n"
                   "2\t0\t3\t112\t5\t0\t0\t0\t0\t0\t0\t1\n")
    assert main(["mission", "upload", str(bad), "--connection", address]) == 2
    err = capsys.readouterr().err
    assert "bad.waypoints" in err and "112" in err
    assert emu.snapshot()["mission_len"] == 0  # nothing was sent
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        dead = f"tcp:127.0.0.1:{s.getsockname()[1]}"
    assert main(["mission", "download", "--connection", dead, "--out", str(tmp_path / "x.plan"),
                 "--timeout", "1"]) == 2
    assert dead in capsys.readouterr().err and not (tmp_path / "x.plan").exists()


def test_upload_of_a_plan_with_a_geofence_sends_it(vehicle, tmp_path, capsys):
    """A .plan's geofence left the vehicle without a fence, silently. Now it goes up first
    (MAV_MISSION_TYPE_FENCE, FENCE_ENABLE 1) and the command says so (tests/mavlink/test_mavlink_fence.py has the rest)."""
    import json

    doc = json.loads(SQUARE.read_text())
    home = doc["mission"]["plannedHomePosition"]
    doc["geoFence"] = {"version": 2, "polygons": [], "circles": [
        {"version": 1, "inclusion": True, "circle": {"center": home[:2], "radius": 200.0}}]}
    plan = tmp_path / "fenced.plan"
    plan.write_text(json.dumps(doc))
    emu, address = vehicle("ardupilot")
    assert main(["mission", "upload", str(plan), "--connection", address]) == 0
    out = capsys.readouterr().out
    assert "fenced.plan" in out and "1 circle(s)" in out and "FENCE_ENABLE 0 -> 1" in out, out
    with emu._lock:
        assert [(it.command, it.param1) for it in emu.missions.fence_items] == [(5003, 200.0)]
    assert emu.params["FENCE_ENABLE"] == 1


HOME = GeoPoint(lat=47.397742, lon=8.545594, alt=488.0)


def _wpl(path, rows):
    """A QGC WPL 110 file: home row, then ``rows`` of (command, frame, p1, p2, east m, north m, z) about HOME."""
    from aerodaas.model.geo import enu_to_geodetic

    lines = ["QGC WPL 110", f"0\t1\t0\t16\t0\t0\t0\t0\t{HOME.lat:.7f}\t{HOME.lon:.7f}\t{HOME.alt:.2f}\t1"]
    for k, (cmd, frame, p1, p2, e, n, z) in enumerate(rows, start=1):
        g = enu_to_geodetic(e, n, 0.0, HOME)
        lat, lon = (g.lat, g.lon) if frame != 2 else (0.0, 0.0)
        lines.append(f"{k}\t0\t{frame}\t{cmd}\t{p1}\t{p2}\t0\t0\t{lat:.7f}\t{lon:.7f}\t{z}\t1")
    path.write_text("\n".join(lines) + "\n")
    return path


#: take off to 5 m, a waypoint, DO_CHANGE_SPEED 5 m/s (ground), a waypoint, land
SPEEDY = [(22, 3, 0, 0, 0, 0, 5.0), (16, 3, 0, 0, 0, 20, 5.0), (178, 2, 1, 5, 0, 0, 0), (16, 3, 0, 0, 20, 20, 5.0),
          (21, 3, 0, 0, 20, 20, 0.0)]


def _stored(emu) -> list[tuple]:
    """(command, param2) of the emulated vehicle's mission, ArduPilot's home item left out."""
    with emu._lock:
        return [(it.command, round(it.param2, 3)) for it in emu.missions.mission[1:]]


def test_items_are_measured_from_the_vehicles_home_not_the_files(vehicle, tmp_path, capsys):
    """A mission 537 m from the vehicle was refused as 9,238 km, measured from the file's planned home.
    A .plan planned at the other end of the world, its items beside the vehicle, goes up; items 537 m from the
    vehicle are refused by --max-distance 500 as 537 m, wherever the file planned its home."""
    import json

    emu, address = vehicle("ardupilot")
    doc = json.loads(SQUARE.read_text())
    doc["mission"]["plannedHomePosition"] = [-33.8568, 151.2153, 10.0]  # Sydney
    far_home = tmp_path / "far_home.plan"
    far_home.write_text(json.dumps(doc))
    assert main(["mission", "upload", str(far_home), "--connection", address]) == 0, capsys.readouterr().err
    capsys.readouterr()
    out = _wpl(tmp_path / "out.waypoints", [(22, 3, 0, 0, 0, 537, 5.0), (21, 3, 0, 0, 0, 537, 0.0)])
    assert main(["mission", "upload", str(out), "--connection", address, "--max-distance", "500"]) == 2
    err = capsys.readouterr().err
    assert "is 537 m from home, beyond max_distance 500 m" in err, err


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_the_files_speeds_go_up_as_written_and_no_parameter_changes(vehicle, tmp_path, capsys, autopilot):
    """DO_CHANGE_SPEED 5 m/s went up as 2 m/s without a word, and --start left WPNAV_SPEED 1000 -> 200,
    WPNAV_SPEED_UP 250 -> 100, WPNAV_SPEED_DN 150 -> 100 on the vehicle. Now the file goes up as written, the
    read-back says so, and every vehicle parameter is as before, also after --start."""
    emu, address = vehicle(autopilot)
    before = dict(emu.params)
    path = _wpl(tmp_path / "speedy.waypoints", SPEEDY)
    assert main(["mission", "upload", str(path), "--connection", address, "--start"]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "read back: the vehicle holds the 5 items as sent" in out, out
    assert _stored(emu)[2] == (178, 5.0) if autopilot == "ardupilot" else True
    assert emu.snapshot()["armed"]
    assert emu.params == before


def test_max_speed_caps_the_files_speeds_and_says_so_per_item(vehicle, tmp_path, capsys):
    """--max-speed 2: the file's DO_CHANGE_SPEED 5 m/s goes up as 2 (said with its item), and since the vehicle's own
    cruise speed (WPNAV_SPEED 1000 cm/s) is above the cap, a DO_CHANGE_SPEED 2 m/s is inserted after the take-off
    (said too); WPNAV_SPEED itself is untouched."""
    emu, address = vehicle("ardupilot")
    path = _wpl(tmp_path / "speedy.waypoints", SPEEDY)
    assert main(["mission", "upload", str(path), "--connection", address, "--max-speed", "2"]) == 0
    out = capsys.readouterr().out
    assert "before item 2 inserted: DO_CHANGE_SPEED 2 m/s (--max-speed 2 m/s; the vehicle's own cruise speed is " \
           "10 m/s)" in out, out
    assert "item 3 (MAV_CMD_DO_CHANGE_SPEED (178)): DO_CHANGE_SPEED 5 m/s capped to 2 m/s (--max-speed 2 m/s)" in out
    assert _stored(emu) == [(22, 0.0), (178, 2.0), (16, 0.0), (178, 2.0), (16, 0.0), (21, 0.0)]
    assert emu.params["WPNAV_SPEED"] == 1000.0


def test_a_mission_the_vehicle_stores_differently_is_not_started(vehicle, tmp_path, capsys):
    """The read-back after the upload: a vehicle that keeps the second waypoint 1e-5 degree off holds another flight:
    exit 2, named, and --start does not arm."""
    emu, address = vehicle("ardupilot")
    store = emu.mission_protocol.store_item

    def shift(link, msg, is_int):
        if getattr(msg, "mission_type", 0) == 0 and msg.seq == 4:
            msg.x += 100
        store(link, msg, is_int)

    emu.mission_protocol.store_item = shift
    path = _wpl(tmp_path / "speedy.waypoints", SPEEDY)
    assert main(["mission", "upload", str(path), "--connection", address, "--start"]) == 2
    err = capsys.readouterr().err
    assert "the mission read back differs from the one sent: item 4 (MAV_CMD_NAV_WAYPOINT (16)): latitude" in err, err
    assert "not started" in err and not emu.snapshot()["armed"]


def test_a_mission_the_vehicle_replaces_right_after_the_upload_goes_up_once_more(vehicle, tmp_path, capsys):
    """PX4 can replace a mission it has just accepted (a mission state published meanwhile): the read-back holds 0
    items. The upload is sent once more, said, and the vehicle then holds the mission as sent."""
    emu, address = vehicle("px4")
    dropped = replace_mission_on_read(emu, 1)
    path = _wpl(tmp_path / "speedy.waypoints", SPEEDY)
    assert main(["mission", "upload", str(path), "--connection", address]) == 0
    out, err = capsys.readouterr()
    assert dropped == [5], dropped
    assert "right after accepting the 5 items the vehicle held 0 (mission: count 5 sent, 0 stored): another " \
           "mission replaced it; uploaded it once more" in err, err
    assert out.count("5 items from") == 1 and "read back: the vehicle holds the 5 items as sent" in out, out
    with emu._lock:
        assert [it.command for it in emu.missions.mission] == [22, 16, 178, 16, 21]


def test_a_mission_the_vehicle_replaces_twice_is_not_started(vehicle, tmp_path, capsys):
    """Replaced again after the second upload: exit 2 naming the count the vehicle holds, and --start does not arm."""
    emu, address = vehicle("px4")
    dropped = replace_mission_on_read(emu, 2)
    path = _wpl(tmp_path / "speedy.waypoints", SPEEDY)
    assert main(["mission", "upload", str(path), "--connection", address, "--start"]) == 2
    err = capsys.readouterr().err
    assert dropped == [5, 5], dropped
    # the first read-back's replacement is said too, before the error
    assert "right after accepting the 5 items the vehicle held 0 (mission: count 5 sent, 0 stored): another " \
           "mission replaced it; uploaded it once more" in err, err
    assert "the mission read back differs from the one sent: mission: count 5 sent, 0 stored; not started" in err, err
    assert not emu.snapshot()["armed"]


def test_a_mission_replaced_before_the_start_is_not_started_and_the_vehicle_is_disarmed(vehicle, tmp_path, capsys):
    """PX4 holds another mission by the time it is armed (another station's upload): its MISSION_CURRENT reports
    another mission id than the upload's ACK gave, so --start exits 2 naming both, never switches to the mission, and
    disarms the vehicle it armed (PX4's own disarm without a take-off, 10 vehicle s at 10x, put off here)."""
    emu, address = vehicle("px4", params={"COM_DISARM_PRFLT": 600.0})
    replaced = replace_mission_on_arm(emu)
    path = _wpl(tmp_path / "speedy.waypoints", SPEEDY)
    assert main(["mission", "upload", str(path), "--connection", address, "--start"]) == 2
    err = capsys.readouterr().err
    assert replaced == [5], replaced
    assert "start_mission: the vehicle reports mission id " in err and "another mission replaced it; not started" \
        in err, err
    snap = emu.snapshot()
    assert not snap["armed"] and "AUTO.MISSION" not in [m for _, m in emu.mode_log], (snap["armed"], emu.mode_log)


NAVTEST = Path(__file__).parents[1] / "data" / "missions" / "CMAC-copter-navtest.waypoints"
CMAC = GeoPoint(lat=-35.363261, lon=149.165230, alt=584.0)


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_a_mission_planner_file_with_frame_3_on_every_item_uploads_starts_and_downloads(tmp_path, capsys, autopilot):
    """Mission Planner's frame 3 on DO_CHANGE_SPEED (item 6) and RTL (item 8). ArduCopter stores them
    in frame 0 (AP_Mission) and the read-back called that a different flight (exit 2, not started); PX4 refuses them
    in a global frame (MAV_MISSION_UNSUPPORTED). Now they go up in MAV_FRAME_MISSION, said per item, the read-back
    compares what each autopilot keeps, and the mission starts; the download flies the same."""
    emu = MavlinkVehicleEmulator(autopilot, speedup=10.0, gps_lock_s=1.0, home=CMAC)
    try:
        address = emu.start("tcp:127.0.0.1:0")
        assert main(["mission", "upload", str(NAVTEST), "--connection", address, "--start"]) == 0, \
            capsys.readouterr().err
        out = capsys.readouterr().out
        for k, cmd in ((6, "DO_CHANGE_SPEED (178)"), (8, "NAV_RETURN_TO_LAUNCH (20)")):
            assert f"item {k} (MAV_CMD_{cmd}): frame MAV_FRAME_GLOBAL_RELATIVE_ALT (3) sent as MAV_FRAME_MISSION (2)" \
                in out, out
        assert "read back: the vehicle holds the 8 items as sent" in out, out
        assert emu.snapshot()["armed"]
        with emu._lock:
            frames = [it.frame for it in (emu.missions.mission[1:] if autopilot == "ardupilot" else emu.missions.mission)]
        assert frames == ([3, 3, 3, 3, 3, 0, 3, 0] if autopilot == "ardupilot" else [3, 3, 3, 3, 3, 2, 3, 2])
        back = tmp_path / "back.waypoints"
        assert main(["mission", "download", "--out", str(back), "--connection", address]) == 0
    finally:
        emu.stop()
    from aerodaas.missionfile.upload import mission_differences

    diffs = mission_differences(load_mission(NAVTEST).expanded_items(), load_mission(back).expanded_items())
    assert not [d for d in diffs if d.flight], diffs
