"""The DJI Tello backend against the Tello SDK 2.0 emulator on loopback UDP."""
from __future__ import annotations

import time

import numpy as np
import pytest

from aerodaas.backends import make_backend
from aerodaas.backends.base import CommandRefused, LinkLost
from aerodaas.backends.tello.protocol import go_command, parse_state
from aerodaas.config import RobotConfig, SensorConfig, TelloConfig
from aerodaas.emulators import free_udp_port
from aerodaas.emulators.tello import TELLO_LIMITS, TelloEmulator, format_state

HEADING = 30.0  # the emulated Tello's power-on heading, compass degrees: makes every frame conversion matter



def _wait(pred, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.02)


@pytest.fixture
def tello(request):
    """(emulator, backend) connected on loopback; per-test options via ``@pytest.mark.tello(emu={}, cfg={})``."""
    mark = request.node.get_closest_marker("tello")
    opts = mark.kwargs if mark else {}
    sp, vp = free_udp_port(), free_udp_port()
    emu = TelloEmulator(state_port=sp, video_port=vp, initial_heading_deg=HEADING, **opts.get("emu", {})).start()
    tcfg = dict(host="127.0.0.1", command_port=emu.command_port, state_port=sp, video_port=vp,
                bind_host="127.0.0.1", initial_heading_deg=HEADING, command_timeout_s=1.0, video=False,
                state_timeout_s=0.5)
    tcfg.update(opts.get("cfg", {}))
    backend = make_backend(RobotConfig(id="tello1", backend="tello", limits=TELLO_LIMITS, tello=TelloConfig(**tcfg)))
    backend.connect(timeout_s=5.0)
    yield emu, backend
    backend.close()
    emu.stop()


def _settle(backend) -> None:
    _wait(lambda: not backend.control.busy, 15.0, "the manoeuvre to finish")
    time.sleep(0.25)  # a couple of state packets after the reply


def _sent(emu, word: str) -> list[str]:
    return [t for _, t in emu.received if t.split(" ", 1)[0] == word]


# ---------------------------------------------------------------------------------------------- pure functions
def test_parse_state_accepts_both_sdk_formats_and_rejects_malformed():
    plain = format_state(pitch=1, roll=-2, yaw=-45, vgx=3, vgy=-4, vgz=0, h_cm=120, bat=87, baro_m=488.5, motor_s=12)
    st = parse_state(plain)
    assert (st["pitch"], st["roll"], st["yaw"], st["vgx"], st["vgy"], st["h"], st["bat"]) == (1, -2, -45, 3, -4, 120, 87)
    assert st["baro"] == pytest.approx(488.5)
    edu = format_state(pitch=0, roll=0, yaw=10, vgx=0, vgy=0, vgz=0, h_cm=0, bat=50, baro_m=1.0, motor_s=0,
                       mission_pad_fields=True)
    assert edu.startswith(b"mid:-2;") and parse_state(edu)["yaw"] == 10
    for bad, why in [(b"", "empty"), (b"\xff\xfe", "ASCII"), (plain.replace(b"yaw:-45", b"yaw:abc"), "'yaw'"),
                     (plain.replace(b"bat:87;", b""), "bat"), (b"pitch;roll:0", "no ':'")]:
        with pytest.raises(ValueError, match=why):
            parse_state(bad)


def test_go_command_body_frame_ranges_and_chunking():
    # facing east (ENU yaw 0): east is forward (+x), north is left (+y)
    assert go_command((1.0, 0.5, 0.3), 0.0, 50) == "go 100 50 30 50"
    # facing north (ENU yaw 90): east is to the right (-y)
    assert go_command((1.0, 0.0, 0.0), 90.0, 50) == "go 0 -100 0 50"
    # 12 m ahead: the first chunk keeps the direction and is clipped to 500 cm on the longest axis
    x, y, z, s = (int(v) for v in go_command((12.0, 6.0, 0.0), 0.0, 500).split()[1:])
    assert (x, y, z, s) == (500, 250, 0, 100)
    # inside the 20 cm dead zone the SDK refuses: nothing to send
    assert go_command((0.15, -0.1, 0.05), 0.0, 50) is None
    assert go_command((0.204, 0.0, 0.0), 0.0, 5) is None  # rounds to 20 cm: still the dead zone
    assert go_command((0.3, 0.0, 0.0), 0.0, 5) == "go 30 0 0 10"  # speed clipped to the SDK's 10 cm/s


# ---------------------------------------------------------------------------------------------- flight
@pytest.mark.tello(cfg={"keepalive_s": 0.3})
def test_takeoff_rc_go_hold_land_reach_expected_positions(tello):
    emu, b = tello
    assert b.state().link_ok and b.state().yaw == pytest.approx(90.0 - HEADING, abs=1.0)  # mission-start reference
    b.actions.arm()
    b.actions.takeoff(1.5)
    _settle(b)
    assert emu.position[2] == pytest.approx(1.5, abs=0.1) and b.state().position[2] == pytest.approx(emu.position[2], abs=0.02)
    assert b.state().in_air and b.telemetry.odometry().in_air
    assert _sent(emu, "takeoff") == ["takeoff"] and len(_sent(emu, "up")) == 1  # takeoff climbs to 0.8 m

    p0, yaw0 = emu.position, emu.yaw_enu
    b.guidance.set_velocity((0.0, 0.5, 0.0), yaw_rate_dps=20.0)  # north at 0.5 m/s, turning counter-clockwise
    time.sleep(1.0)
    moved = emu.position - p0
    assert moved[1] > 0.3 and abs(moved[0]) < 0.2 and abs(moved[2]) < 0.05, moved
    assert emu.yaw_enu - yaw0 > 10.0  # counter-clockwise in ENU
    assert b.state().yaw == pytest.approx(emu.yaw_enu, abs=3.0)
    assert np.linalg.norm(b.state().position - emu.position) < 0.15, (b.state().position, emu.position)  # dead reckoning

    target = np.array([2.0, -1.0, 1.2])  # east-south-down from a yawed vehicle: no axis is a body axis
    b.guidance.goto(target, speed=1.0)  # replaces the velocity command
    _settle(b)
    for go in _sent(emu, "go"):
        x, y, z, s = (int(v) for v in go.split()[1:])
        assert all(abs(c) <= 500 for c in (x, y, z)) and 10 <= s <= 100 and max(abs(x), abs(y), abs(z)) > 20
    assert np.linalg.norm(emu.position - target) < 0.2, emu.position  # the vehicle flew there
    assert np.linalg.norm(b.state().position - emu.position) < 0.1, (b.state().position, emu.position)  # and we know it
    time.sleep(0.8)  # keep-alives while hovering must not resume the old velocity
    assert np.linalg.norm(emu.position - target) < 0.2 and b.state().velocity == pytest.approx(np.zeros(3), abs=0.1)

    x0 = float(emu.position[0])
    b.guidance.goto((5.0, -1.0, 1.2), speed=0.5)
    _wait(lambda: emu.position[0] > x0 + 0.3, 15.0, "the go to be under way")
    b.guidance.hold()  # stops the running go
    assert not b.control.busy and _sent(emu, "stop") == ["stop"]
    _wait(lambda: np.linalg.norm(emu.vehicle.state.velocity) < 0.02, 15.0, "the stop")
    stopped = emu.position
    assert x0 + 0.3 < stopped[0] < 4.5, stopped  # stopped on the way, short of the go's end (5.0)
    time.sleep(0.4)
    assert np.linalg.norm(emu.position - stopped) < 0.05

    b.guidance.land()
    _settle(b)
    assert not emu.in_air and not b.state().in_air and b.state().position[2] == pytest.approx(0.0, abs=0.02)
    odo = b.telemetry.odometry()
    assert odo.battery_pct == pytest.approx(emu.vehicle.battery_pct, abs=1.5)
    assert b.drain_events() == []


def test_refused_command_carries_the_tello_reply(tello):
    emu, b = tello
    with pytest.raises(CommandRefused) as ei:
        b.guidance.goto((1.0, 0.0, 1.0))  # on the ground: the Tello refuses motion
    assert ei.value.result == "error Motor stop" and ei.value.command.startswith("go ")  # the SDK text sent
    with pytest.raises(CommandRefused, match="out of range"):
        b.link.command("speed 500")
    assert b.link.command("battery?") == str(int(emu.vehicle.battery_pct))


def test_lost_replies_are_retried_without_flying_twice(tello):
    emu, b = tello
    emu.drop_next_reply("speed")
    assert b.link.command("speed 50") == "ok"
    assert _sent(emu, "speed") == ["speed 50", "speed 50"] and b.link.stats["retries"] == 1

    b.actions.takeoff(0.8)
    _settle(b)
    emu.drop_next_reply("go")
    b.guidance.goto((1.0, 0.0, 0.8), speed=1.0)
    _settle(b)
    assert emu.dropped_replies == 2
    assert len(_sent(emu, "go")) == 1  # the go was done: re-checking the position, not re-sending it
    assert np.linalg.norm(emu.position[:2] - (1.0, 0.0)) < 0.2 and b.drain_events() == []


def test_malformed_state_packets_are_counted_and_skipped(tello):
    emu, b = tello
    before = b.link.stats["malformed_state"]
    emu.send_raw_state(b"pitch:0;roll:0;yaw:oops;")
    emu.send_raw_state(b"\x00\x01garbage")
    emu.send_raw_state(b"ok")
    _wait(lambda: b.link.stats["malformed_state"] >= before + 3, 2.0, "the malformed packets")
    time.sleep(0.3)
    assert b.link.stats["malformed_state"] == before + 3 and b.state().link_ok
    assert b.state().yaw == pytest.approx(90.0 - HEADING, abs=1.0) and b.state().battery_pct == pytest.approx(90.0, abs=1.0)


def test_link_lost_and_regained(tello):
    emu, b = tello
    b.step(0.0)
    emu.state_paused = True
    _wait(lambda: not b.state().link_ok, 2.0, "the link to be lost")
    b.step(0.0)
    with pytest.raises(LinkLost):
        b.actions.takeoff(1.0)
    emu.state_paused = False
    _wait(lambda: b.state().link_ok, 2.0, "the link to come back")
    b.step(0.0)
    assert [e["event"] for e in b.drain_events()] == ["link_lost", "link_regained"]


@pytest.mark.tello(emu={"auto_land_s": 1.0}, cfg={"keepalive_s": 0.3})
def test_keepalive_keeps_the_tello_flying(tello):
    emu, b = tello
    b.actions.takeoff(0.8)
    _settle(b)
    # more than twice the emulated 1.0 s auto-land time without any application command (waited on the keep-alives
    # themselves, so a loaded host sending them late is not a shorter test)
    _wait(lambda: b.link.stats["keepalives"] >= 8, 30.0, "eight keep-alives")
    assert emu.in_air and emu.auto_landings == 0
    assert all(t == "rc 0 0 0 0" for t in _sent(emu, "rc"))
    b.close()  # no more keep-alives: the emulated Tello lands by itself
    _wait(lambda: not emu.in_air, 6.0, "the emulated Tello to land by itself")
    assert emu.auto_landings == 1


@pytest.mark.tello(emu={"video_size": (320, 240), "video_fps": 15.0, "camera_pitch_deg": 35.0},
                   cfg={"video": True})
def test_video_frames_decode_to_the_rendered_view(tello):
    emu, b = tello
    assert _sent(emu, "streamon") == ["streamon"]
    _wait(lambda: b.link.stats["video_frames"] >= 3, 10.0, "decoded video frames")
    b.actions.takeoff(0.8)  # up where the camera sees the ground's texture
    _settle(b)
    n = b.link.stats["video_frames"]
    _wait(lambda: b.link.stats["video_frames"] >= n + 3, 5.0, "frames of the hovering Tello")
    frame, t = b.camera.frame()
    assert frame.shape == (240, 320, 3) and frame.dtype == np.uint8
    assert 0.0 < t <= b.t
    sent = emu.sent_frames[-1][2]  # the vehicle hovers still: every rendered frame is the same view
    mad = float(np.abs(frame.astype(np.int16) - sent.astype(np.int16)).mean())
    other = emu.render(emu.position, emu.yaw_enu + 90.0)
    mad_other = float(np.abs(frame.astype(np.int16) - other.astype(np.int16)).mean())
    assert mad < 6.0 and mad_other > 3 * mad, (mad, mad_other)
    assert b.link.stats["video_errors"] == 0


@pytest.mark.tello(emu={"refuse": {"streamon": "error"}}, cfg={"video": True})
def test_refused_streamon_without_a_backend_camera_is_a_video_error_event(tello):
    """No camera takes its frames from this Tello: a refused ``streamon`` does not fail the connection, it is a
    ``video_error`` event carrying the reply, and no frames come."""
    emu, b = tello
    assert _sent(emu, "streamon") == ["streamon"] and b.state().link_ok
    events = b.drain_events()
    assert [e["event"] for e in events] == ["video_error"]
    assert events[0]["command"] == "streamon" and events[0]["reply"] == "error"
    assert "streamon refused: error" in events[0]["reason"] and b.link.last_status == "error"
    time.sleep(0.5)
    assert b.camera.frame() is None and emu.frames_sent == 0 and b.link.stats["video_datagrams"] == 0
    assert b.link.command("battery?") == str(int(emu.vehicle.battery_pct))  # otherwise a working Tello


def test_refused_streamon_fails_connect_when_a_camera_needs_the_video():
    """A camera sensor with ``source: backend`` needs the Tello's video: a refused ``streamon`` fails connect()
    with CommandRefused naming the command, the Tello's reply and the sensor, and the backend is closed."""
    sp, vp = free_udp_port(), free_udp_port()
    emu = TelloEmulator(state_port=sp, video_port=vp, refuse={"streamon": "error"}).start()
    cam = SensorConfig(id="cam", type="camera", properties={"source": "backend", "width": 960, "height": 720})
    tcfg = TelloConfig(host="127.0.0.1", command_port=emu.command_port, state_port=sp, video_port=vp,
                       bind_host="127.0.0.1", command_timeout_s=1.0, video=True)
    b = make_backend(RobotConfig(id="tello1", backend="tello", limits=TELLO_LIMITS, tello=tcfg, sensors=[cam]))
    try:
        with pytest.raises(CommandRefused) as ei:
            b.connect(timeout_s=5.0)
        e = ei.value
        assert e.command == "streamon" and e.result == "error"
        assert "'cam'" in e.status_text and "properties.source 'backend'" in e.status_text
        assert str(e).startswith("robot 'tello1': streamon refused: error")
        assert _sent(emu, "streamon") == ["streamon"]  # a refusal is an answer: not re-sent
        assert b.link.closed  # closed: sockets and threads released
    finally:
        b.close()
        emu.stop()
