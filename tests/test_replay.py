"""Replay of recorded flights: a real PX4 telemetry log as a non-navigable backend, an MCAP camera channel as a
frame source, and the camera ``source`` configuration."""
from __future__ import annotations

import json
import time

import numpy as np
import pymap3d
import pytest

from aerodaas.backends import make_backend
from aerodaas.backends.base import NotNavigable
from aerodaas.backends.replay import McapCameraReplay
from aerodaas.config import ConfigError, RobotConfig, ReplayConfig, SensorConfig, parse_environment_config
from aerodaas.recording import McapRecorder

from .conftest import DATA_DIR

TLOG = DATA_DIR / "tlogs" / "thayer_rural.tlog"
needs_tlog = pytest.mark.skipif(not TLOG.is_file(), reason=f"{TLOG} not found (set AERODAAS_DATA_DIR)")
RATE = 100.0


@pytest.fixture(scope="module")
def raw():
    """Expectations straight from the raw log, without the backend's code: every message of the autopilot
    (system 1, component 1) with its time since the log's first record."""
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(TLOG))
    out, t0 = [], None
    while (m := conn.recv_msg()) is not None:
        t0 = m._timestamp if t0 is None else t0
        if m.get_type() != "BAD_DATA" and (m.get_srcSystem(), m.get_srcComponent()) == (1, 1):
            out.append((m._timestamp - t0, m.get_type(), m))
    conn.close()
    return out


@pytest.fixture(scope="module")
def replayed():
    """The whole log replayed at RATE x: (backend, samples [(odometry, battery)], events, wall seconds)."""
    b = make_backend(RobotConfig(id="px4", backend="replay", replay=ReplayConfig(log=str(TLOG), rate=RATE)))
    b.connect()
    t_start = time.monotonic()
    samples, events = [], []
    while not b.finished:
        b.step(0.0)
        samples.append((b.odometry(), b.battery_pct))
        events += b.drain_events()
        time.sleep(0.01)
    wall = time.monotonic() - t_start
    b.close()
    return b, samples, events, wall


@needs_tlog
def test_replayed_odometry_and_battery_match_the_log(replayed, raw):
    b, samples, _, wall = replayed
    gpi = [(t, m) for t, ty, m in raw if ty == "GLOBAL_POSITION_INT"]
    homes = [(t, m) for t, ty, m in raw if ty == "HOME_POSITION"]
    bats = [(t, m.battery_remaining) for t, ty, m in raw if ty == "BATTERY_STATUS"]

    def last_before(seq, t):
        prior = [x for x in seq if x[0] <= t]
        return prior[-1] if prior else None

    checked = 0
    for odo, bat in samples:
        g = last_before(gpi, odo.t)
        if g is None:
            continue
        h = (last_before(homes, g[0]) or homes[0])[1]  # home: the latest HOME_POSITION, else the first one
        e, n, _ = pymap3d.geodetic2enu(g[1].lat / 1e7, g[1].lon / 1e7, g[1].alt / 1e3,
                                       h.latitude / 1e7, h.longitude / 1e7, h.altitude / 1e3)
        assert odo.position == pytest.approx((e, n, g[1].relative_alt / 1e3), abs=1e-3), odo.t
        assert (odo.geodetic.lat, odo.geodetic.lon) == pytest.approx((g[1].lat / 1e7, g[1].lon / 1e7), abs=1e-9)
        assert bat == last_before(bats, odo.t)[1]
        checked += 1
    assert checked > 100
    # the flight went 30 m up and came back; the replay clock ran at RATE x and reached the log's end
    assert max(s[0].position[2] for s in samples) > 25.0
    assert samples[-1][0].t >= b.duration_s > 300.0
    assert b.duration_s / RATE <= wall < b.duration_s / RATE + 10.0  # generous: a shared 2-core machine


@needs_tlog
def test_replay_events_mission_modes_statustext_without_duplicates(replayed, raw):
    from pymavlink import mavutil

    b, _, events, _ = replayed
    kinds = [e["event"] for e in events]
    assert kinds[-1] == "replay_finished" and all(e["t"] <= events[-1]["t"] for e in events)

    reached = [e["seq"] for e in events if e["event"] == "mission_item_reached"]
    assert reached == sorted({m.seq for _, ty, m in raw if ty == "MISSION_ITEM_REACHED"}) == list(range(8))

    texts = {}  # STATUSTEXT by its MAVLink 2 id: the log holds each twice (two links)
    for _, ty, m in raw:
        if ty == "STATUSTEXT":
            texts.setdefault(m.id, m.text.rstrip("\x00").strip())
    got = [e["text"] for e in events if e["event"] == "status_text"]
    assert got == list(texts.values()) and "Takeoff detected" in got and b.info["duplicates"] > 1000

    modes, armed = [], []
    for _, ty, m in raw:
        if ty == "HEARTBEAT":
            name = mavutil.mode_string_v10(m)
            if not modes or modes[-1] != name:
                modes.append(name)
            a = bool(m.base_mode & 128)
            if (armed[-1] if armed else False) != a:
                armed.append(a)
    assert [e["name"] for e in events if e["event"] == "mode"] == modes
    assert modes[:2] == ["MISSION", "RTL"] and "MANUAL" in modes  # PX4 custom modes decoded
    assert [e["event"] for e in events if e["event"] in ("armed", "disarmed")] == \
        ["armed" if a else "disarmed" for a in armed]


@needs_tlog
def test_replay_is_not_navigable():
    b = make_backend(RobotConfig(id="px4", backend="replay", replay=ReplayConfig(log=str(TLOG))))
    assert b.navigable is False and b.kind == "replay" and b.clock == "vehicle"
    calls = {"arm": (), "disarm": (), "takeoff": (5.0,), "goto": ((1.0, 2.0, 3.0),), "set_velocity": ((1, 0, 0),),
             "hold": (), "land": (), "return_to_launch": ()}
    for name, args in calls.items():
        with pytest.raises(NotNavigable, match=f"not navigable; {name} is not possible"):
            getattr(b, name)(*args)


def test_replay_rejects_bad_logs(tmp_path):
    from aerodaas.backends.base import BackendError

    for name, data in (("empty.tlog", b""), ("noise.tlog", bytes(range(256)) * 8)):
        p = tmp_path / name
        p.write_bytes(data)
        b = make_backend(RobotConfig(id="r", backend="replay", replay=ReplayConfig(log=str(p))))
        with pytest.raises(BackendError, match="replay.log"):
            b.connect()


def test_replay_refuses_px4_ulog_in_the_config():
    """ULog is not supported: the environment file is refused (field and value named) before any actor starts."""
    from aerodaas.config import ConfigError, parse_environment_config

    with pytest.raises(ConfigError, match=r"replay\.log.*\.ulg logs are not supported.*flight\.ulg"):
        parse_environment_config({"name": "r", "robots": [{"id": "r", "backend": "replay",
                                                            "replay": {"log": "flight.ulg"}}]})


# ---------------------------------------------------------------------------------------------- MCAP camera
T0 = 1_700_000_000_000_000_000  # ns


def _frame(i: int) -> np.ndarray:
    yy, xx = np.mgrid[0:96, 0:128]
    img = np.stack([(xx * 2 + i * 20) % 256, (yy * 2) % 256, np.full_like(xx, 60 + 30 * i)], axis=-1)
    return img.astype(np.uint8)


def test_mcap_camera_replay_frames_and_times(tmp_path):
    path = tmp_path / "flight.mcap"
    with McapRecorder(path, jpeg_quality=95) as rec:
        rec.write_json("/mission/state", T0, {"state": "IDLE"}, schema_name="aerodaas.MissionState")
        for i in range(5):
            rec.write_image("/d1/camera/cam", T0 + (500 + 200 * i) * 1_000_000, _frame(i))
    cam = McapCameraReplay(path, "/d1/camera/cam")
    assert len(cam) == 5 and cam.times == pytest.approx([0.5, 0.7, 0.9, 1.1, 1.3])
    for i, (t, img) in enumerate(cam):
        assert img.shape == (96, 128, 3) and img.dtype == np.uint8
        assert np.abs(img.astype(int) - _frame(i)).mean() < 3.0  # JPEG q95
        assert np.abs(img.astype(int) - _frame((i + 1) % 5)).mean() > 10.0
    assert cam.frame_at(0.4) is None
    img, t = cam.frame_at(0.95)
    assert t == pytest.approx(0.9) and np.abs(img.astype(int) - _frame(2)).mean() < 3.0
    assert cam.frame_at(99.0)[1] == pytest.approx(1.3)
    with pytest.raises(ValueError, match=r"'/d1/camera/nope' not found.*'/d1/camera/cam'"):
        McapCameraReplay(path, "/d1/camera/nope")
    with pytest.raises(ValueError, match="not foxglove.CompressedImage"):
        McapCameraReplay(path, "/mission/state")


def test_camera_source_config(tmp_path, monkeypatch):
    assert SensorConfig(id="c", type="camera").properties["source"] == "sim"
    with pytest.raises(ValueError, match=r"properties.source must be one of \['sim', 'backend', 'mcap'\], got 'usb'"):
        SensorConfig(id="c", type="camera", properties={"source": "usb"})
    with pytest.raises(ValueError, match="properties.mcap must name the MCAP recording"):
        SensorConfig(id="c", type="camera", properties={"source": "mcap"})
    with pytest.raises(ValueError, match="properties.topic is only used with properties.source 'mcap'"):
        SensorConfig(id="c", type="camera", properties={"topic": "/a"})
    with pytest.raises(ValueError, match="'backend' needs a backend with its own camera stream"):
        RobotConfig(id="d1", sensors=[SensorConfig(id="c", type="camera", properties={"source": "backend"})])
    RobotConfig(id="d1", backend="tello", sensors=[SensorConfig(id="c", type="camera", properties={"source": "backend"})])

    (tmp_path / "rec").mkdir()
    (tmp_path / "rec" / "flight.mcap").write_bytes(b"")
    monkeypatch.setenv("AERODAAS_DATA_DIR", str(tmp_path))
    env = {"robots": [{"id": "d1", "sensors": [{"id": "cam", "type": "camera",
                                                "properties": {"source": "mcap", "mcap": "rec/flight.mcap"}}]}]}
    cfg = parse_environment_config(json.loads(json.dumps(env)))
    props = cfg.robots[0].sensors[0].properties
    assert props["mcap"] == str((tmp_path / "rec" / "flight.mcap").resolve()) and props["topic"] == "/d1/camera/cam"
    env["robots"][0]["sensors"][0]["properties"]["mcap"] = "rec/missing.mcap"
    with pytest.raises(ConfigError, match=r"robots.0.sensors.0.properties.mcap: file 'rec/missing.mcap' not found"):
        parse_environment_config(env)
