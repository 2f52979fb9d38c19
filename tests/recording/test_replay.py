"""Replay of recorded flights: a real PX4 telemetry log as a non-navigable backend, an MCAP camera channel as a
frame source, and the camera ``source`` configuration."""
from __future__ import annotations

import json

import numpy as np
import pymap3d
import pytest

from aerodaas.backends import make_backend
from aerodaas.backends.base import NotNavigable
from aerodaas.backends.replay import McapCameraReplay
from aerodaas.config import ConfigError, RobotConfig, ReplayConfig, SensorConfig, parse_environment_config
from aerodaas.recording.writer import McapRecorder

from tests.conftest import DATA_DIR, needs_path

TLOG = DATA_DIR / "tlogs" / "thayer_rural.tlog"
needs_tlog = needs_path(TLOG, reason="the flight log of the shared data (set AERODAAS_DATA_DIR)")
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


class _FakeClock:
    """time.monotonic for the replay module: advanced by hand, so the samples do not depend on the machine's load."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture(scope="module")
def replayed():
    """The whole log replayed at RATE x on a hand-driven wall clock (0.01 s steps, i.e. RATE x 0.01 s of log time
    each): (backend, samples [(odometry, battery)], events, wall seconds of that clock)."""
    import aerodaas.backends.replay as replay_mod

    clock = _FakeClock()
    mp = pytest.MonkeyPatch()
    mp.setattr(replay_mod.time, "monotonic", clock)
    try:
        b = make_backend(RobotConfig(id="px4", backend="replay", replay=ReplayConfig(log=str(TLOG), rate=RATE)))
        b.connect()
        t_start = clock()
        samples, events = [], []
        while not b.finished:
            b.step(0.0)
            samples.append((b.telemetry.odometry(), b.state().battery_pct))
            events += b.drain_events()
            clock.now += 0.01
        wall = clock() - t_start
        b.close()
    finally:
        mp.undo()
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
    # the replay clock runs at RATE x its wall clock: it finished within a step of duration / RATE (+ the step that
    # saw it finish)
    assert b.duration_s / RATE <= wall < b.duration_s / RATE + 0.021


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
            getattr(b.actions if name in ("arm", "disarm", "takeoff") else b.guidance, name)(*args)


def test_replay_rejects_bad_logs(tmp_path):
    from aerodaas.backends.base import BackendError

    for name, data in (("empty.tlog", b""), ("noise.tlog", bytes(range(256)) * 8)):
        p = tmp_path / name
        p.write_bytes(data)
        b = make_backend(RobotConfig(id="r", backend="replay", replay=ReplayConfig(log=str(p))))
        with pytest.raises(BackendError, match="replay.log"):
            b.connect()


# ---------------------------------------------------------------------------------------------- PX4 ULog
def write_ulog(path, topics: dict, logs: list, start_us: int = 1_000_000) -> None:
    """A minimal ULog v1 file written from the format spec (docs.px4.io, "ULog File Format"), not by the code under
    test: header (magic, version, start µs), flag bits, one format per topic, then subscriptions ('A'), data ('D')
    and text ('L') in time order. ``topics``: name -> ([(c type, field name)], [row dicts with ``timestamp``]);
    ``logs``: (timestamp µs, level 0-7, text)."""
    import struct

    out = bytearray(b"ULog\x01\x12\x35" + bytes([1]) + struct.pack("<Q", start_us))

    def put(kind: str, payload: bytes) -> None:
        out.extend(struct.pack("<HB", len(payload), ord(kind)) + payload)

    put("B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
    codes = {"uint64_t": "Q", "int32_t": "i", "uint8_t": "B", "float": "f", "double": "d", "bool": "?"}
    for name, (fields, _) in topics.items():
        put("F", (name + ":" + "".join(f"{t} {n};" for t, n in fields)).encode())
    put("I", bytes([len("char[5] ver_sw")]) + b"char[5] ver_sw" + b"test1")
    records = []
    for msg_id, (name, (fields, rows)) in enumerate(topics.items()):
        put("A", struct.pack("<BH", 0, msg_id) + name.encode())
        fmt = "<" + "".join(f"{t.split('[')[1][:-1]}{codes[t.split('[')[0]]}" if "[" in t else codes[t] for t, _ in fields)
        for row in rows:
            values = [v for _, n in fields for v in (row[n] if isinstance(row[n], (list, tuple)) else [row[n]])]
            records.append((row["timestamp"], "D", struct.pack("<H", msg_id) + struct.pack(fmt, *values)))
    for ts, level, text in logs:
        records.append((ts, "L", struct.pack("<BQ", ord(str(level)), ts) + text.encode()))
    for _, kind, payload in sorted(records, key=lambda r: r[0]):
        put(kind, payload)
    path.write_bytes(bytes(out))


HOME = (47.397742, 8.545594, 488.0)  # lat, lon deg, alt m AMSL


def _flight(t: float) -> tuple[float, float]:
    """The synthetic flight: (north m, height m) at log time t s — climb to 10 m, 50 m north at 2.5 m/s, descend."""
    h = min(10.0, max(0.0, (t - 2.0) * 2.0)) if t < 40.0 else max(0.0, 10.0 - (t - 40.0) * 1.0)
    return min(50.0, max(0.0, (t - 8.0) * 2.5)), h


@pytest.fixture(scope="module")
def ulog_file(tmp_path_factory):
    return write_ulog_flight(tmp_path_factory.mktemp("ulog") / "flight.ulg")


def write_ulog_flight(path):
    """60 s of a PX4 flight at 10 Hz: POSCTL disarmed, armed TAKEOFF at 2 s, MISSION at 8 s, LAND at 40 s, landed
    and disarmed at 52 s; mission items 0-2 reached at 8, 28 and 40 s; battery 100 % -> 76 %; heading east.
    Returns ``path``."""
    start = 1_000_000
    gpos, lpos, att, bat, status, land, mres = [], [], [], [], [], [], []
    for i in range(600):
        t = i / 10.0
        ts = start + int(t * 1e6)
        north, h = _flight(t)
        lat, lon, alt = pymap3d.enu2geodetic(0.0, north, h, *HOME)
        gpos.append({"timestamp": ts, "lat": lat, "lon": lon, "alt": alt})
        vn = 2.5 if 8.0 < t < 28.0 else 0.0
        lpos.append({"timestamp": ts, "x": north, "y": 0.0, "z": -h, "vx": vn, "vy": 0.0, "vz": 0.0})
        att.append({"timestamp": ts, "q": [np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)]})  # yaw 90 deg (east)
        bat.append({"timestamp": ts, "voltage_v": 16.8 - 0.02 * t, "remaining": 1.0 - 0.004 * t})
        armed = 2.0 <= t < 52.0
        nav = 2 if t < 2.0 else 17 if t < 8.0 else 3 if t < 40.0 else 18 if t < 52.0 else 2
        status.append({"timestamp": ts, "arming_state": 2 if armed else 1, "nav_state": nav})
        land.append({"timestamp": ts, "landed": not (2.5 <= t < 50.0)})
        mres.append({"timestamp": ts, "seq_reached": -1 if t < 8.0 else 0 if t < 28.0 else 1 if t < 40.0 else 2})
    topics = {
        "vehicle_global_position": ([("uint64_t", "timestamp"), ("double", "lat"), ("double", "lon"),
                                     ("float", "alt")], gpos),
        "vehicle_local_position": ([("uint64_t", "timestamp"), ("float", "x"), ("float", "y"), ("float", "z"),
                                    ("float", "vx"), ("float", "vy"), ("float", "vz")], lpos),
        "vehicle_attitude": ([("uint64_t", "timestamp"), ("float[4]", "q")], att),
        "battery_status": ([("uint64_t", "timestamp"), ("float", "voltage_v"), ("float", "remaining")], bat),
        "vehicle_status": ([("uint64_t", "timestamp"), ("uint8_t", "arming_state"), ("uint8_t", "nav_state")],
                           status),
        "vehicle_land_detected": ([("uint64_t", "timestamp"), ("bool", "landed")], land),
        "home_position": ([("uint64_t", "timestamp"), ("double", "lat"), ("double", "lon"), ("float", "alt")],
                          [{"timestamp": start + 500_000, "lat": HOME[0], "lon": HOME[1], "alt": HOME[2]}]),
        "mission_result": ([("uint64_t", "timestamp"), ("int32_t", "seq_reached")], mres),
    }
    write_ulog(path, topics, [(start + 2_600_000, 6, "Takeoff detected"), (start + 51_000_000, 4, "Landing detected")],
               start_us=start)
    return path


def test_replay_plays_a_px4_ulog(ulog_file, monkeypatch):
    """Positions, height above home, battery, heading, modes, arming, landed state, mission items and the log's
    text messages come out of a .ulg as they do from a .tlog (the expectations come from the flight's own
    definition, not from the reader)."""
    import aerodaas.backends.replay as replay_mod

    clock = _FakeClock()  # hand-driven: the number of samples does not depend on the machine's load
    monkeypatch.setattr(replay_mod.time, "monotonic", clock)
    b = make_backend(RobotConfig(id="px4", backend="replay", replay=ReplayConfig(log=str(ulog_file), rate=RATE)))
    assert b.navigable is False
    b.connect()
    assert (b.home.lat, b.home.lon) == pytest.approx(HOME[:2], abs=1e-7) and b.home.alt == pytest.approx(HOME[2])
    assert b.info["format"] == "ulog" and "vehicle_status" in b.info["topics"]
    samples, events = [], []
    while not b.finished and clock.now < 1000.0 + 60.0 / RATE + 5:
        b.step(0.0)
        samples.append((b.telemetry.odometry().t, b.state().position.copy(), b.state().battery_pct, b.state().in_air, b.state().yaw))
        events += b.drain_events()
        clock.now += 0.00037  # 0.037 s of log per step, off the 0.1 s sample grid
    assert b.finished
    checked = 0
    for t, pos, bat, in_air, yaw in samples:
        if 1.0 < t < 59.0 and abs(t * 10 - round(t * 10)) > 0.2:  # away from sample edges
            north, h = _flight(np.floor(t * 10) / 10)
            assert pos[0] == pytest.approx(0.0, abs=0.05) and pos[1] == pytest.approx(north, abs=0.05), (t, pos)
            assert pos[2] == pytest.approx(h, abs=0.05), (t, pos)
            assert bat == pytest.approx(100 * (1.0 - 0.004 * np.floor(t * 10) / 10), abs=1.0)
            assert in_air == (2.5 <= np.floor(t * 10) / 10 < 50.0), t
            assert yaw == pytest.approx(0.0, abs=0.5)  # heading east = ENU yaw 0
            checked += 1
    assert checked > 50
    kinds = [e["event"] for e in events]
    assert [e["name"] for e in events if e["event"] == "mode"] == ["POSCTL", "TAKEOFF", "MISSION", "LAND", "POSCTL"]
    assert kinds.count("armed") == 1 and kinds.count("disarmed") == 1
    assert [e["seq"] for e in events if e["event"] == "mission_item_reached"] == [0, 1, 2]
    assert [(e["severity"], e["text"]) for e in events if e["event"] == "status_text"] == [
        (6, "Takeoff detected"), (4, "Landing detected")]  # MAV_SEVERITY_INFO, _WARNING
    assert "link_lost" not in kinds  # an onboard log has no link to lose
    with pytest.raises(NotNavigable):
        b.guidance.goto((0.0, 0.0, 5.0))


def test_replay_rejects_a_bad_ulog(tmp_path):
    from aerodaas.backends.base import BackendError

    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"not a ulog at all" * 10)
    b = make_backend(RobotConfig(id="r", backend="replay", replay=ReplayConfig(log=str(bad))))
    with pytest.raises(BackendError, match=r"replay\.log.*bad\.ulg.*not a readable ULog"):
        b.connect()
    nopos = tmp_path / "nopos.ulg"
    write_ulog(nopos, {"battery_status": ([("uint64_t", "timestamp"), ("float", "remaining")],
                                          [{"timestamp": 2_000_000, "remaining": 0.5}])}, [])
    b = make_backend(RobotConfig(id="r", backend="replay", replay=ReplayConfig(log=str(nopos))))
    with pytest.raises(BackendError, match="no vehicle_global_position"):
        b.connect()


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
    with pytest.raises(ValueError, match=r"properties.source: unknown camera source 'usb': one of \['sim', 'backend', "
                                         r"'mcap'\], an rtsp://"):
        SensorConfig(id="c", type="camera", properties={"source": "usb"})
    with pytest.raises(ValueError, match="properties.mcap must name the MCAP recording"):
        SensorConfig(id="c", type="camera", properties={"source": "mcap"})
    with pytest.raises(ValueError, match="properties.topic is only used with properties.source 'mcap'"):
        SensorConfig(id="c", type="camera", properties={"topic": "/a"})
    with pytest.raises(ValueError, match="'backend' needs a backend with its own camera stream"):
        RobotConfig(id="d1", sensors=[SensorConfig(id="c", type="camera", properties={"source": "backend"})])
    RobotConfig(id="d1", backend="tello", sensors=[SensorConfig(id="c", type="camera", properties={"source": "backend"})])
    # the capability is the backend class's own declaration: a plug-in backend with a camera needs no framework edit
    from aerodaas.backends.sim import SimBackend
    from aerodaas.plugins import register_backend

    @register_backend
    class CameraSim(SimBackend):
        kind = "camera_sim_test"
        provides_camera = True

    RobotConfig(id="d1", backend="camera_sim_test",
                sensors=[SensorConfig(id="c", type="camera", properties={"source": "backend"})])
    with pytest.raises(ValueError, match=r"provides_camera: \[.*'camera_sim_test'.*\]\), but backend is 'sim'"):
        RobotConfig(id="d1", sensors=[SensorConfig(id="c", type="camera", properties={"source": "backend"})])

    (tmp_path / "rec").mkdir()
    with McapRecorder(tmp_path / "rec" / "flight.mcap", jpeg_quality=80) as rec:  # checked before Ray: a real one
        rec.write_image("/d1/camera/cam", T0, _frame(0))
    monkeypatch.setenv("AERODAAS_DATA_DIR", str(tmp_path))
    env = {"robots": [{"id": "d1", "sensors": [{"id": "cam", "type": "camera",
                                                "properties": {"source": "mcap", "mcap": "rec/flight.mcap"}}]}]}
    cfg = parse_environment_config(json.loads(json.dumps(env)))
    props = cfg.robots[0].sensors[0].properties
    assert props["mcap"] == str((tmp_path / "rec" / "flight.mcap").resolve()) and props["topic"] == "/d1/camera/cam"
    env["robots"][0]["sensors"][0]["properties"]["mcap"] = "rec/missing.mcap"
    with pytest.raises(ConfigError, match=r"robots.0.sensors.0.properties.mcap: file 'rec/missing.mcap' not found"):
        parse_environment_config(env)
