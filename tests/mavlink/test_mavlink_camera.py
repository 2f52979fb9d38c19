"""``source: "mavlink"``: a camera reads the video stream the vehicle announces (MAVLink camera protocol v2).

Fast: discovery by the MAVLink backend against the emulated vehicle with an emulated camera component (no stream
behind the URL): the URL found, a chosen camera and stream, the older request commands, a clear error naming the
robot, the sensor and what was asked when there is no camera; the announced URI as a camera source; the
configuration refused before Ray on a backend that cannot discover. Slow (``video``): apps/vehicle_tracking.py
unchanged on the MAVLink emulator whose camera announces the rig's GStreamer RTSP server: detections in the
recording and the discovered URL recorded and summarised (fails, not skips, without the rig, as the other video
tests)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from aerodaas.backends.mavlink import MavlinkBackend
from aerodaas.config import MavlinkConfig, RobotConfig
from aerodaas.emulators.mavlink.gimbal import EmulatedCamera
from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
from aerodaas.video.discovery import StreamDiscoveryError, StreamRequest, VideoStreamType, stream_source
from tests.inputs.cli_inprocess import run_cli
from tests.conftest import REPO, needs_data


@pytest.fixture
def vehicle():
    """vehicle(camera or None, autopilot) -> (emulator, connected backend); both stopped after the test."""
    made: list = []

    def make(camera: EmulatedCamera | None, autopilot: str = "ardupilot"):
        emu = MavlinkVehicleEmulator(autopilot, speedup=5.0, gps_lock_s=0.5)
        made.append(emu)
        emu.attach_camera(camera)
        addr = emu.start("tcp:127.0.0.1:0")
        b = MavlinkBackend(RobotConfig(id="quad", backend="mavlink", mavlink=MavlinkConfig(connection=addr)))
        made.append(b)
        b.connect(timeout_s=30)
        return emu, b

    yield make
    for obj in reversed(made):
        obj.close() if isinstance(obj, MavlinkBackend) else obj.stop()


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_the_announced_stream_is_found(vehicle, autopilot):
    emu, b = vehicle(EmulatedCamera("rtsp://10.0.0.7:8554/main.264", resolution=(1920, 1080)), autopilot)
    got = b.discover_video_stream(StreamRequest("quad", "cam1", timeout_s=30))
    assert got.source == got.uri == "rtsp://10.0.0.7:8554/main.264"
    assert (got.component, got.stream_id, got.stream_type) == (M.MAV_COMP_ID_CAMERA, 1, VideoStreamType.RTSP)
    assert got.camera == "AeroDaaS emulated camera" and got.resolution == (1920, 1080) and got.codec == "h264"
    # asked at its own component id, with MAV_CMD_REQUEST_MESSAGE, as camera protocol v2 says
    assert (M.MAV_CMD_REQUEST_MESSAGE, M.MAV_COMP_ID_CAMERA) in emu.camera_requests
    # a camera asked for by its component id and stream id
    again = b.discover_video_stream(StreamRequest("quad", "cam1", camera_component=M.MAV_COMP_ID_CAMERA,
                                                  stream_id=1, timeout_s=30))
    assert again.source == got.source


def test_an_rtp_port_announced_as_qgroundcontrol_does_becomes_an_rtp_source(vehicle):
    _, b = vehicle(EmulatedCamera("5600", kind=M.VIDEO_STREAM_TYPE_RTPUDP))
    got = b.discover_video_stream(StreamRequest("quad", "cam1", timeout_s=30))
    assert got.uri == "5600" and got.source == "rtp://0.0.0.0:5600"


def test_no_camera_is_a_clear_error_naming_robot_sensor_and_request(vehicle):
    _, b = vehicle(None)
    with pytest.raises(StreamDiscoveryError) as e:
        b.discover_video_stream(StreamRequest("quad", "cam1", timeout_s=1.5))
    msg = str(e.value)
    assert "robot 'quad' camera 'cam1'" in msg and "within 1.5 s" in msg and "any camera" in msg
    assert "no camera HEARTBEAT" in msg and "the autopilot component 1" in msg  # what the vehicle said
    assert "MAV_RESULT_" in msg  # the autopilot refused to send CAMERA_INFORMATION: said, not hidden


def test_a_stream_the_camera_does_not_have_is_named(vehicle):
    _, b = vehicle(EmulatedCamera("rtsp://127.0.0.1:8554/cam"))
    with pytest.raises(StreamDiscoveryError, match=r"stream 7; heard camera HEARTBEATs from components \[100\].*"
                                                   r"streams: 1 'main' uri 'rtsp://127.0.0.1:8554/cam'"):
        b.discover_video_stream(StreamRequest("quad", "cam1", stream_id=7, timeout_s=1.5))


@pytest.mark.parametrize("kind,uri,source", [
    (VideoStreamType.RTSP, "rtsp://192.168.144.25:8554/main.264", "rtsp://192.168.144.25:8554/main.264"),
    (VideoStreamType.RTPUDP, "5600", "rtp://0.0.0.0:5600"),
    (VideoStreamType.RTPUDP, "udp://192.168.2.1:5600", "rtp://192.168.2.1:5600"),  # mavlink-camera-manager's form
    (VideoStreamType.MPEG_TS, "5000", "udp://0.0.0.0:5000"),
    (VideoStreamType.MPEG_TS, "udp://0.0.0.0:5000", "udp://0.0.0.0:5000"),
    (VideoStreamType.TCP_MPEG, "192.168.2.2:8000", "tcp://192.168.2.2:8000"),
])
def test_announced_uris_as_camera_sources(kind, uri, source):
    from aerodaas.video.source import parse_stream_source

    assert stream_source(kind, uri) == source
    parse_stream_source(source)  # readable as a configured source


def _env(source_props: dict, backend: dict) -> dict:
    env = json.loads((REPO / "apps" / "vehicle_tracking.json").read_text())
    env["robots"][0]["sensors"][0]["properties"].update(source_props)
    env["robots"][0].update(backend)
    env["simulation"] = {"speedup": 1, "lockstep": False, "physics_hz": 50}
    return env


def test_mavlink_source_on_another_backend_is_refused_before_ray(tmp_path):
    env_path = tmp_path / "env.json"
    env_path.write_text(json.dumps(_env({"source": "mavlink"}, {})))
    proc = run_cli("run", str(REPO / "apps" / "vehicle_tracking.py"), "--env", str(env_path), "--quiet")
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "sensors.0.properties.source: 'mavlink'" in proc.stderr and "backend is 'sim'" in proc.stderr
    assert "ray" not in proc.stdout.lower()


@pytest.mark.parametrize("props,match", [
    ({"source": "rtsp://cam/x", "stream_id": 2}, r"properties.stream_id is only used with properties.source "
                                                 r"'mavlink'"),
    ({"source": "mavlink", "discovery_timeout_s": 500.0}, r"discovery_timeout_s"),
    ({"source": "mavlink", "camera_component": 0}, r"camera_component"),
    ({"source": "mavlink", "codec": "vp8"}, r"properties.codec must be one of \['h264', 'h265'\], got 'vp8'"),
])
def test_discovery_properties_are_checked(props, match):
    from aerodaas.config import SensorConfig

    with pytest.raises(ValueError, match=match):
        SensorConfig(id="c", type="camera", properties=props)


@pytest.mark.video
@needs_data
def test_vehicle_tracking_reads_the_stream_the_vehicle_announces(tmp_path, monkeypatch):
    """The app unchanged on the MAVLink emulator (real time) whose camera component announces the rig's RTSP URL;
    the environment says only ``source: "mavlink"``."""
    from aerodaas.config import load_environment_config
    from aerodaas.recording.metrics import load_run
    from tests.video.video_rig import QUICK_LIMITS, RtspServer, check_stream_recording, make_footage

    footage = make_footage(tmp_path / "pan.mp4", seconds=8.0, empty_s=22.0)
    server = RtspServer(footage)
    robot = load_environment_config(REPO / "apps" / "vehicle_tracking.json").robots[0]
    emu = MavlinkVehicleEmulator("ardupilot", robot=robot, speedup=1.0)
    emu.attach_camera(EmulatedCamera(server.url, resolution=(640, 480), framerate_hz=10.0))
    addr = emu.start("tcp:127.0.0.1:0")
    env = _env({"source": "mavlink", "discovery_timeout_s": 30.0},
               {"backend": "mavlink", "mavlink": {"connection": addr, "autopilot": "ardupilot"}})
    env["robots"][0]["limits"].update(QUICK_LIMITS)  # the discovery and the stream are under test, not the pace
    env_path = tmp_path / "vt_mavlink_camera.json"
    env_path.write_text(json.dumps(env))
    rec = tmp_path / "run.mcap"
    monkeypatch.setenv("AERODAAS_STATE_DIR", str(tmp_path / "state"))
    try:
        server.start()
        proc = subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", str(REPO / "apps" / "vehicle_tracking.py"),
                               "--env", str(env_path), "--record", str(rec), "--timeout", "400"],
                              capture_output=True, text=True, timeout=600, env=dict(os.environ))
    finally:
        server.stop_all()
        emu.stop()
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-3000:]
    run = load_run(str(rec))
    found = [e for e in run["events"] if e["event"] == "video_discovered"]
    assert len(found) == 1 and found[0]["url"] == server.url and found[0]["component"] == M.MAV_COMP_ID_CAMERA, found
    assert f"{server.url} announced over MAVLink by camera component 100" in out  # in the summary
    assert sum(1 for _, boxes in run["detections"] if boxes) >= 5  # cars in the real footage
    got = check_stream_recording(rec)  # every frame accounted for, every pose tag at its capture time
    assert got["stats"]["source"] == server.url and got["stats"]["discovered"].startswith("announced over MAVLink")


@needs_data  # the app's detector model
def test_a_run_without_the_announced_camera_fails_naming_it(tmp_path, ray_session):
    """The whole run (in-process, on the pytest worker's shared Ray session): no camera on the vehicle -> the
    robot's error says so, exit code 1, before take-off."""
    emu = MavlinkVehicleEmulator("ardupilot", speedup=1.0, gps_lock_s=0.5)
    addr = emu.start("tcp:127.0.0.1:0")
    env = _env({"source": "mavlink", "discovery_timeout_s": 2.0},
               {"backend": "mavlink", "mavlink": {"connection": addr, "autopilot": "ardupilot"}})
    env_path = tmp_path / "env.json"
    env_path.write_text(json.dumps(env))
    try:
        proc = run_cli("run", str(REPO / "apps" / "vehicle_tracking.py"), "--env", str(env_path), "--record",
                       str(tmp_path / "run.mcap"), shared_ray=True)
        armed = emu.snapshot()["armed"] or emu.state.took_off
    finally:
        emu.stop()
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1, out[-3000:]
    assert "StreamDiscoveryError: robot 'quadrotor_base' camera 'cam1': properties.source 'mavlink' found no video " \
           "stream within 2 s" in out, out[-3000:]
    assert not armed  # handed back untouched
