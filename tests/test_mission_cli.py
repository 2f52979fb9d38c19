"""``aerodaas mission upload`` / ``download`` against the emulated ArduPilot and PX4 vehicles (loopback TCP)."""
from __future__ import annotations

import socket

import pytest

from aerodaas.cli import main
from aerodaas.emulators.mavlink_vehicle import MavlinkVehicleEmulator
from aerodaas.missionfile import load_mission
from aerodaas.app.models import GeoPoint

from .conftest import DATA_DIR

SQUARE = DATA_DIR / "missions" / "qgc_test_simple_square.plan"  # take-off + 4-waypoint square


@pytest.fixture
def vehicle():
    made: list = []

    def make(autopilot: str) -> tuple[MavlinkVehicleEmulator, str]:
        emu = MavlinkVehicleEmulator(autopilot, speedup=10.0, gps_lock_s=1.0,
                                     home=GeoPoint(lat=47.397742, lon=8.545594, alt=488.0))
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
    """issue 26: a .plan's geofence left the vehicle without a fence, silently. Now it goes up first
    (MAV_MISSION_TYPE_FENCE, FENCE_ENABLE 1) and the command says so (tests/test_mavlink_fence.py has the rest)."""
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
    assert "fenced.plan" in out and "1 circle(s)" in out and "FENCE_ENABLE 1" in out, out
    with emu._lock:
        assert [(it.command, it.param1) for it in emu.fence_items] == [(5003, 200.0)]
    assert emu.params["FENCE_ENABLE"] == 1
