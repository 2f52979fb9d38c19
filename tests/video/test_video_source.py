"""Video stream camera sources (aerodaas.video): the source grammar checked before Ray, the capture clock, the pose
at capture, and the reader against real encoded footage — a file, and MPEG-TS and RTP H.264 on UDP from a sender
process that is killed and restarted (an outage). No Ray here: the missions flown on streams are in
test_video_missions.py (slow group ``video``)."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest

from aerodaas.backends.base import PoseSample
from aerodaas.config import ConfigError
from aerodaas.config.robot import SensorConfig
from aerodaas.video import CaptureClock, StreamReader, VideoSourceError, parse_stream_source
from aerodaas.video.pose import pose_at, pose_sampled_at
from tests.inputs.cli_inprocess import run_cli
from tests.conftest import DATA_MISSING, REPO, needs_data, skip_or_fail
from tests.video.video_rig import RtspServer, Sender, check_pose_tags, free_udp_port, make_footage


@pytest.mark.parametrize("source,kind,fmt", [
    ("rtsp://192.168.144.25:8554/main.264", "rtsp", "rtsp"),
    ("rtsps://cam.local/live", "rtsp", "rtsp"),
    ("rtp://0.0.0.0:5600", "rtp", "sdp"),
    ("rtp://:5600", "rtp", "sdp"),
    ("udp://127.0.0.1:5000", "mpegts_udp", "mpegts"),
    ("/dev/video0", "v4l2", "video4linux2"),
    ("cam.sdp", "sdp", "sdp"),
    ("clip.mp4", "file", None),
    ("file:///data/clip.MKV", "file", None),
])
def test_stream_sources_accepted(source, kind, fmt):
    spec = parse_stream_source(source)
    assert (spec.kind, spec.format) == (kind, fmt)
    assert spec.live == (kind != "file")
    if kind == "rtsp":
        assert spec.options["rtsp_transport"] == "tcp"
    if kind == "rtp":  # QGC's UDP 5600 has no SDP: we describe it (RFC 4566), H.264 on payload type 96
        assert spec.port == 5600 and "m=video 5600 RTP/AVP 96" in spec.sdp_text()
        assert "a=rtpmap:96 H264/90000" in spec.sdp_text()
    assert parse_stream_source("rtp://0.0.0.0:5600", codec="h265").sdp_text().count("H265/90000") == 1


@pytest.mark.parametrize("source,props,match", [
    ("usb", {}, r"properties.source: unknown camera source 'usb'"),
    ("http://cam/stream", {}, r"unknown camera source 'http://cam/stream'"),
    ("rtsp:///path", {}, r"'rtsp:///path' names no host"),
    ("rtsp://cam:99999/x", {}, r"invalid port"),
    ("rtp://0.0.0.0", {}, r"needs a UDP/TCP port in \[1, 65535\]"),
    ("udp://1.2.3.4:5000/path", {}, r"host:port only"),
    (" rtsp://cam/x", {}, r"without surrounding blanks"),
    ("rtsp://cam/x", {"transport": "quic"}, r"properties.transport must be 'tcp' or 'udp', got 'quic'"),
    ("rtp://0.0.0.0:5600", {"codec": "vp8"}, r"properties.codec must be one of \['h264', 'h265'\], got 'vp8'"),
    ("udp://0.0.0.0:5000", {"transport": "tcp"}, r"properties.transport is only used with an rtsp:// source"),
    ("rtsp://cam/x", {"codec": "h264"}, r"properties.codec is only used with an rtp:// source"),
    ("sim", {"stall_timeout_s": 3.0}, r"properties.stall_timeout_s is only used with a video stream source"),
    ("rtsp://cam/x", {"first_frame_timeout_s": 0}, r"properties.first_frame_timeout_s must be a finite number "
                                                    r"within \(0, 600\]"),
    ("rtsp://cam/x", {"stall_timeout_s": "2"}, r"properties.stall_timeout_s must be a finite number"),
])
def test_bad_stream_sources_name_the_property(source, props, match):
    with pytest.raises(ValueError, match=match):
        SensorConfig(id="c", type="camera", properties={"source": source, **props})


def _env_with_camera(tmp_path: Path, props: dict, simulation: dict | None = None) -> Path:
    env = json.loads((REPO / "apps" / "vehicle_tracking.json").read_text())
    env["robots"][0]["sensors"][0]["properties"].update(props)
    env["simulation"] = simulation or {"speedup": 1, "lockstep": False}
    env.pop("world")
    p = tmp_path / "env.json"
    p.write_text(json.dumps(env))
    return p


def test_environment_resolves_a_video_file_and_refuses_a_missing_one(tmp_path):
    from aerodaas.config import load_environment_config as load_environment

    (tmp_path / "clip.mp4").write_bytes(b"\0")
    cfg = load_environment(str(_env_with_camera(tmp_path, {"source": "clip.mp4"})))
    assert cfg.robots[0].sensors[0].properties["source"] == str(tmp_path / "clip.mp4")
    with pytest.raises(ConfigError, match=r"robots.0.sensors.0.properties.source.*'gone.mp4'"):
        load_environment(str(_env_with_camera(tmp_path, {"source": "gone.mp4"})))


def test_a_stream_camera_needs_the_wall_clock_refused_before_ray(tmp_path):
    """A live stream cannot run at speedup 10 or wait in lock-step: exit 2 before Ray, naming the camera."""
    from tests.inputs.test_app_value import _ray_processes_under, fresh_ray_tmp

    env = _env_with_camera(tmp_path, {"source": "udp://127.0.0.1:5999"}, {"speedup": 10, "lockstep": True})
    ray_tmp = fresh_ray_tmp(tmp_path)
    p = run_cli("run", str(REPO / "apps" / "vehicle_tracking.py"), "--env", str(env), "--quiet", cwd=tmp_path,
                env={**os.environ, "RAY_TMPDIR": str(ray_tmp)})  # in-process: Ray refused
    assert p.returncode == 2, p.stdout + p.stderr
    assert "quadrotor_base/cam1" in p.stderr + p.stdout and "speedup must be 1" in p.stderr + p.stdout
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []  # no Ray session was started


def test_capture_clock_takes_the_fastest_frame_as_transit_floor_and_reanchors_on_a_restart():
    c = CaptureClock()
    assert c.capture(10.0, 100.30) == pytest.approx(100.30)  # first frame: its own arrival
    assert c.capture(10.1, 100.35) == pytest.approx(100.35)  # faster: the floor moves (offset 90.25)
    assert c.capture(10.2, 100.60) == pytest.approx(100.45)  # slower (jitter): capture keeps the sender's spacing
    assert c.capture(0.0, 101.00) == pytest.approx(101.00)  # PTS went back: the sender restarted
    assert c.resets == 1
    assert c.capture(None, 7.0) == 7.0


def test_pose_at_interpolates_between_samples_and_along_the_short_yaw_arc():
    poses = [(0.0, (0.0, 0.0, 10.0), 170.0), (0.1, (1.0, 0.0, 10.0), -170.0), (0.2, (2.0, 1.0, 10.0), -160.0)]
    pos, yaw, t = pose_at(poses, 0.05)
    assert pos == pytest.approx((0.5, 0.0, 10.0)) and yaw == pytest.approx(-180.0) and t == 0.05
    pos, yaw, t = pose_at(poses, 0.15)
    assert pos == pytest.approx((1.5, 0.5, 10.0)) and yaw == pytest.approx(-165.0)
    assert pose_at(poses, -1.0)[2] == 0.0 and pose_at(poses, 9.0)[2] == 0.2  # clamped: says which sample


def test_pose_sampled_at_names_the_samples_it_used():
    poses = [(0.0, (0.0, 0.0, 10.0), 0.0), (0.1, (1.0, 0.0, 10.0), 10.0), (0.2, (2.0, 0.0, 10.0), 20.0)]
    pos, yaw, t, samples = pose_sampled_at(poses, 0.15)
    assert pos == pytest.approx((1.5, 0.0, 10.0)) and yaw == pytest.approx(15.0) and (t, samples) == (0.15, (0.1, 0.2))
    assert pose_sampled_at(poses, 0.3)[2:] == (0.2, (0.2,)) and pose_sampled_at([], 1.0)[3] == ()


def _flight_timing(pose_of: str, latency_s: float = 0.5, speed: float = 5.0) -> tuple[list, list]:
    """A fabricated stream run: a drone flying east at ``speed`` m/s while swaying north (position
    (speed t, 2 sin t, 16) m), its 10 Hz odometry, the camera's poses at its 20 Hz ticks, and a 10 fps stream whose
    frames arrive ``latency_s`` after capture. Each frame's FrameTiming is tagged as the camera does
    (:func:`pose_sampled_at` on the ticks) at ``pose_of``: ``capture`` (right), ``arrival`` (the newest pose: wrong),
    or ``arrival_relabelled`` (the arrival's position under the capture's sample times). Returns (timing,
    odometry)."""
    import math

    def state(t):
        return (speed * t, 2.0 * math.sin(t), 16.0), (speed, 2.0 * math.cos(t), 0.0)

    odometry = [{"t": k / 10, "position": list(state(k / 10)[0]), "velocity": list(state(k / 10)[1])}
                for k in range(201)]
    ticks = [(k / 20, state(k / 20)[0], 0.0) for k in range(401)]
    timing = []
    for k in range(5, 190):
        capture = k / 10 + 0.013
        arrival = capture + latency_s
        known = [p for p in ticks if p[0] <= arrival]  # what the camera has at the frame's hand-off
        pos, yaw, pose_t, samples = pose_sampled_at(known, arrival if pose_of != "capture" else capture)
        if pose_of == "arrival_relabelled":
            samples = pose_sampled_at(known, capture)[3]
        timing.append({"seq": k, "capture_t": capture, "arrival_t": arrival, "pose_t": pose_t, "position": list(pos),
                       "yaw": yaw, "pose_samples_t": list(samples), "pose_wait_s": 0.0})
    return timing, odometry


def test_the_pose_tag_check_fails_on_a_pose_taken_at_arrival():
    """tests/video/video_rig.check_pose_tags (what every stream run's recording is judged by) passes the camera's own
    tagging and fails a pose taken at the frame's arrival instead of its capture, by its sample times and, when
    those are relabelled, by its position against the odometry (0.5 s late at 5 m/s: 2.5 m, beyond the 1.7 m the
    sample gaps allow)."""
    timing, odometry = _flight_timing("capture")
    got = check_pose_tags(timing, odometry)
    assert got["compared"] == got["judged"] > 150 and got["worst_m"] < 0.05
    with pytest.raises(AssertionError, match=r"pose from the samples at \[.*\] s, captured at"):
        check_pose_tags(*_flight_timing("arrival"))
    with pytest.raises(AssertionError, match=r"m from the odometry there"):
        check_pose_tags(*_flight_timing("arrival_relabelled"))
    with pytest.raises(AssertionError, match=r"pose from the samples at"):  # the newest sample's, 0.19 s after capture
        check_pose_tags(*_flight_timing("arrival", latency_s=0.2))
    # a recording whose odometry surrounds no frame compares zero poses: that is a failure, never a pass
    timing, odometry = _flight_timing("capture")
    for few in ([], odometry[:1], [o for o in odometry if o["t"] > 19.5]):
        with pytest.raises(AssertionError, match=r"no pose tag was compared with the odometry"):
            check_pose_tags(timing, few)


def test_a_held_pose_passes_only_when_the_camera_waited_for_a_newer_sample():
    """Samples that reached the camera late (a loaded machine: the recorded odometry shows no such gap): for five
    frames the camera held a sample 0.4 s older than the capture. check_pose_tags passes them when their FrameTiming
    says the camera waited its full POSE_WAIT_S for a newer sample, and fails the same poses from a camera that did
    not wait (a stale pose while newer samples were there)."""
    import math

    from aerodaas.actors.sensors.camera import POSE_WAIT_S

    timing, odometry = _flight_timing("capture")

    def stalled(wait_s: float) -> list[dict]:
        out = [dict(m) for m in timing]
        for m in out[50:55]:
            t0 = round(m["capture_t"] - 0.4, 1)  # an older 20 Hz tick's sample, the vehicle's own position then
            m.update(pose_samples_t=[t0], pose_t=t0, position=[5.0 * t0, 2.0 * math.sin(t0), 16.0], pose_wait_s=wait_s)
        return out

    got = check_pose_tags(stalled(POSE_WAIT_S), odometry)
    assert got["held"] == 5 and got["compared"] == got["judged"] > 150
    with pytest.raises(AssertionError, match=r"pose from the samples at \[.*\] s, captured at .* waited 0.0 s"):
        check_pose_tags(stalled(0.0), odometry)
    assert check_pose_tags(timing, odometry)["held"] == 0  # interpolated poses: none held


def test_angles_at_interpolates_each_angle_along_the_short_arc():
    from aerodaas.video.pose import angles_at

    samples = [(0.0, (0.0, -10.0, 170.0)), (0.1, (0.0, -30.0, -170.0))]
    (roll, pitch, yaw), t = angles_at(samples, 0.025)
    assert (roll, pitch, yaw, t) == pytest.approx((0.0, -15.0, 175.0, 0.025))
    assert angles_at(samples, 0.05)[0][2] == pytest.approx(-180.0)  # across +-180, not through 0
    assert angles_at(samples, 5.0) == ((0.0, -30.0, -170.0), 0.1) and angles_at([], 1.0) is None


def test_a_stream_frame_carries_the_gimbal_attitude_of_its_capture_time():
    """The camera keeps the gimbal's attitude of every tick; a stream frame captured between two ticks gets the
    attitude interpolated at its capture time, not the one of the tick that delivered it."""
    from collections import deque

    from aerodaas.actors.sensors.camera import CameraComponent
    from aerodaas.navigation.gimbal import euler_from_quaternion
    from aerodaas.protocol.gimbal import GimbalAttitude

    reports = iter([GimbalAttitude(t=10.0, q=(1.0, 0.0, 0.0, 0.0), roll_deg=0.0, pitch_deg=-10.0, yaw_deg=20.0),
                    GimbalAttitude(t=10.2, q=(1.0, 0.0, 0.0, 0.0), roll_deg=0.0, pitch_deg=-50.0, yaw_deg=40.0)])

    class Gimbal:
        def latest(self):
            return next(reports)

    class Backend:
        gimbal = Gimbal()

    cam = CameraComponent.__new__(CameraComponent)  # only the gimbal bookkeeping, no plane or stream
    cam.backend, cam._gimbals = Backend(), deque(maxlen=256)
    cam._gimbal(1.0)
    tick = cam._gimbal(1.2)
    g = cam._gimbal_at(1.05, tick)  # captured a quarter of the way between the ticks
    assert (g.pitch_deg, g.yaw_deg) == pytest.approx((-20.0, 25.0))
    assert euler_from_quaternion(g.q) == pytest.approx((0.0, -20.0, 25.0), abs=1e-6)  # q agrees with the angles
    assert cam._gimbal_at(1.05, None) is None  # no gimbal: none


class _FakeStream:
    """A stream reader's consumer side holding frames put by the test (no thread, no FFmpeg)."""

    def __init__(self) -> None:
        self.slot = None

    def put(self, capture_mono: float, seq: int) -> None:
        import numpy as np

        from aerodaas.video.reader import VideoFrame

        img = np.zeros((120, 160, 3), np.uint8)
        img.flags.writeable = False
        self.slot = VideoFrame(seq, img, capture_mono, capture_mono + 0.02, None)

    def take(self):
        f, self.slot = self.slot, None
        return f

    def waiting(self) -> bool:
        return self.slot is not None

    def drain_events(self) -> list:
        return []


class _InlinePlane:
    """A data plane that runs every job at once in the caller's thread and keeps what is published."""

    def __init__(self) -> None:
        self.published: list = []
        self.copies = type("Copies", (), {"count": lambda self, what: None})()

    def submit(self, fn, *args) -> None:
        fn(*args)

    def publish(self, cid, msgs, tok, inline=False) -> None:
        self.published += msgs


def test_a_stream_frame_is_handed_off_when_it_arrives_not_at_the_next_tick():
    """A stream camera captures a frame when the reader says it arrived (no poll on the clock's tick);
    the ticks give the poses it is tagged with (interpolated at its capture time between the two ticks around it),
    nothing is captured before the first tick or after the drone's mission ended, and a tick takes only a frame
    that is waiting."""
    from aerodaas.actors.sensors.camera import CameraComponent

    plane = _InlinePlane()
    cam = CameraComponent(plane, "cam", "uav", "cam1", {"width": 160, "height": 120, "hfov_deg": 78, "fps": 10,
                                                        "pitch_deg": 90}, None, None, None, 0)
    stream = cam.stream = _FakeStream()
    stream.put(time.monotonic(), 1)
    cam._on_stream_frame()  # before the clock's first tick: it waits for the tick
    assert plane.published == [] and stream.waiting()
    assert cam.try_capture(PoseSample(1.0, (0.0, 0.0, 10.0), 0.0), 1.0, None)  # the first tick takes the waiting frame
    assert len(plane.published) == 1 and not stream.waiting()
    assert not cam.try_capture(PoseSample(1.5, (2.0, 0.0, 10.0), 0.0), 1.5, None)  # a tick with nothing waiting captures nothing
    tick_mono = cam._tick_clock[1]
    stream.put(tick_mono - 0.25, 2)  # captured half-way between the two ticks, arriving now
    cam._on_stream_frame()  # the arrival alone hands it off
    assert len(plane.published) == 2
    msg = plane.published[-1]
    assert msg.meta.capture_time == pytest.approx(1.25, abs=1e-3)
    assert msg.meta.pose.position == pytest.approx((1.0, 0.0, 10.0), abs=1e-2)  # between the ticks' poses
    assert (msg.meta.seq, cam.ticks, cam.frames, cam.dropped_at_camera) == (2, 2, 2, 0)
    cam.halt()  # the mission is over: an arrival is no longer captured
    stream.put(time.monotonic(), 3)
    cam._on_stream_frame()
    assert len(plane.published) == 2 and stream.waiting()


def test_a_stream_frame_takes_its_pose_from_the_vehicle_samples_own_times():
    """A MAVLink vehicle's newest position sample is older than the tick that reads it (one
    telemetry interval at most). The frame's pose is interpolated between the samples at their own times, not at
    the ticks': captured at 1.25 s between samples of 0.8 s (x 0 m) and 1.3 s (x 5 m), it is at x 4.5 m (stamped
    with the ticks' times, 1.0 and 1.5 s, it would be at 2.5 m). A frame captured after the newest sample waits
    for the next one, and without one holds the newest (its pose time is that sample's)."""
    from aerodaas.actors.sensors.camera import CameraComponent

    plane = _InlinePlane()
    cam = CameraComponent(plane, "cam", "uav", "cam1", {"width": 160, "height": 120, "hfov_deg": 78, "fps": 10,
                                                        "pitch_deg": 90}, None, None, None, 0)
    stream = cam.stream = _FakeStream()
    assert not cam.try_capture(PoseSample(0.8, (0.0, 0.0, 10.0), 0.0), 1.0, None)
    assert not cam.try_capture(PoseSample(0.8, (0.0, 0.0, 10.0), 0.0), 1.25, None)  # the same sample: kept once
    assert not cam.try_capture(PoseSample(1.3, (5.0, 0.0, 10.0), 0.0), 1.5, None)
    assert [p[0] for p in cam._poses] == [0.8, 1.3]
    tick_mono = cam._tick_clock[1]
    stream.put(tick_mono - 0.25, 1)  # captured at run time 1.25 s
    cam._on_stream_frame()
    meta = plane.published[-1].meta
    assert meta.capture_time == pytest.approx(1.25, abs=1e-3)
    assert meta.pose.position == pytest.approx((4.5, 0.0, 10.0), abs=1e-2)
    assert meta.pose_time == pytest.approx(1.25, abs=1e-3)  # interpolated: the pose is of the capture time
    stream.put(tick_mono - 0.05, 2)  # captured at 1.45 s, after the newest sample (1.3 s); no newer one comes
    cam._on_stream_frame()
    meta = plane.published[-1].meta
    assert meta.pose.position == pytest.approx((5.0, 0.0, 10.0), abs=1e-6)
    assert meta.pose_time == 1.3  # held: the pose is of that sample's time


@pytest.fixture(scope="module")
def footage(tmp_path_factory):
    if DATA_MISSING is not None:
        skip_or_fail(DATA_MISSING)
    return make_footage(tmp_path_factory.mktemp("video") / "pan.mp4", seconds=3.0)


def _pump(reader: StreamReader, until, deadline_s: float = 120.0) -> list:
    """Take frames until ``until(frames, events)`` holds (a generous deadline, not a timing bound)."""
    frames, events = [], []
    end = time.monotonic() + deadline_s
    while not until(frames, events):
        assert time.monotonic() < end, (reader.stats(), events)
        f = reader.take()
        if f is not None:
            frames.append(f)
        events += reader.drain_events()
        time.sleep(0.01)
    return frames, events


@needs_data
def test_a_file_plays_at_its_rate_looped_each_frame_delivered_once(footage):
    r = StreamReader(parse_stream_source(str(footage)), 320, 240).start()
    try:
        r.wait_first(60)
        frames, _ = _pump(r, lambda f, e: r.stats()["decoded"] >= 45)  # 3 s of 10 fps: past the first loop
    finally:
        r.close()
    st = r.stats()
    seqs = [f.seq for f in frames]
    assert seqs == sorted(set(seqs)), "a frame delivered twice or out of order"
    assert st["decoded"] == st["taken"] + st["overwritten"] + st["waiting"]
    assert st["opens"] >= 2 and st["lost"] == 0  # looped by reopening; a file's end is not an outage
    assert frames[0].image.shape == (240, 320, 3) and not frames[0].image.flags.writeable


def _survive_outage(r: StreamReader, stop, start) -> tuple[list, dict]:
    """Frames from ``r``; ``stop()`` (the sender or server dies: a link outage) until ``video_lost`` is queued;
    ``start()`` until ``video_restored`` and frames again (generous deadlines, no timing bound). Returns (the frames
    taken, the events by kind)."""
    r.wait_first(60)
    before, _ = _pump(r, lambda f, e: len(f) >= 5)
    stop()
    _, lost = _pump(r, lambda f, e: any(x.kind == "video_lost" for x in e))
    start()
    after, restored = _pump(r, lambda f, e: any(x.kind == "video_restored" for x in e) and len(f) >= 5)
    return before + after, {e.kind: e for e in lost + restored}


def _assert_survived(r: StreamReader, frames: list, ev: dict, source: str) -> None:
    """One outage of ``source``, both events naming it, counters that add up, no frame delivered twice."""
    assert ev["video_lost"].fields["url"] == source
    assert ev["video_restored"].fields["outage_s"] > 0 and ev["video_restored"].mono > ev["video_lost"].mono
    seqs = [f.seq for f in frames]
    assert seqs == sorted(set(seqs))
    st = r.stats()
    assert (st["lost"], st["restored"]) == (1, 1) and st["decoded"] == st["taken"] + st["overwritten"] + st["waiting"], \
        (st, ev)
    assert all(f.capture_mono <= f.arrival_mono for f in frames)
    assert frames[0].image.shape == (240, 320, 3)


@needs_data
@pytest.mark.parametrize("scheme,codec", [("udp", "h264"), ("rtp", "h264"), ("rtp", "h265")])
def test_a_udp_stream_survives_an_outage_with_events(footage, scheme, codec):
    """MPEG-TS and QGC-style RTP H.264 and H.265 (RFC 7798; no SDP from the sender) on UDP: frames arrive, the
    sender dies (a link outage), video_lost is queued; it comes back, video_restored with the outage; no frame
    delivered twice."""
    url = f"{scheme}://127.0.0.1:{free_udp_port()}"
    sender = Sender(footage, url, codec).start()
    r = StreamReader(parse_stream_source(url, codec=codec if scheme == "rtp" else None), 320, 240,
                     stall_timeout_s=1.0).start()
    try:
        frames, ev = _survive_outage(r, sender.stop, sender.start)
    finally:  # the reader first: a server stopping under it would be a second outage
        r.close()
        sender.stop()
    _assert_survived(r, frames, ev, url)


@needs_data
def test_an_sdp_file_describes_the_senders_rtp(footage, tmp_path):
    """``source: /path/cam.sdp``: the sender's own SDP file (RFC 4566; H.264 payload 96 with RFC 6184's
    packetization-mode 1, as FFmpeg's and GStreamer's senders write it), here written by hand for the rig's RTP
    sender; read, through an outage, like raw RTP."""
    port = free_udp_port()
    sdp = tmp_path / "cam.sdp"
    sdp.write_text("v=0\r\no=- 0 0 IN IP4 127.0.0.1\r\ns=rig sender\r\nc=IN IP4 127.0.0.1\r\nt=0 0\r\n"
                   f"m=video {port} RTP/AVP 96\r\na=rtpmap:96 H264/90000\r\na=fmtp:96 packetization-mode=1\r\n")
    spec = parse_stream_source(str(sdp))
    assert (spec.kind, spec.url, spec.live) == ("sdp", str(sdp), True)
    sender = Sender(footage, f"rtp://127.0.0.1:{port}").start()
    r = StreamReader(spec, 320, 240, stall_timeout_s=1.0).start()
    try:
        frames, ev = _survive_outage(r, sender.stop, sender.start)
    finally:  # the reader first: a server stopping under it would be a second outage
        r.close()
        sender.stop()
    _assert_survived(r, frames, ev, str(sdp))


def _udp_sockets() -> set[str]:
    """The inodes of the UDP sockets this process holds (its /proc/self/fd against /proc/net/udp and udp6)."""
    import os

    inodes = set()
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        with open(table) as f:
            inodes |= {line.split()[9] for line in list(f)[1:]}
    held = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:[") and target[8:-1] in inodes:
            held.add(target[8:-1])
    return held


@needs_data
def test_rtsp_with_udp_transport_survives_a_server_outage(footage):
    """``transport: "udp"``: the RTSP session (GStreamer's gst-rtsp-server) carries its RTP on UDP client ports —
    this process holds at least two more UDP sockets (RTP and RTCP) while it reads — and the server's death and
    return are an outage like any other."""
    server = RtspServer(footage)
    try:
        server.start()
    except AssertionError as e:  # the rig's Debian packages are missing: fails in CI
        skip_or_fail(str(e))
    idle = _udp_sockets()
    r = StreamReader(parse_stream_source(server.url, transport="udp"), 320, 240, stall_timeout_s=1.0).start()
    try:
        r.wait_first(60)
        assert len(_udp_sockets() - idle) >= 2, "the RTSP session's media is not on UDP"
        frames, ev = _survive_outage(r, server.stop, server.start)
    finally:  # the reader first: a server stopping under it would be a second outage
        r.close()
        server.stop_all()
    _assert_survived(r, frames, ev, server.url)


def test_no_first_frame_is_an_error_naming_the_url():
    url = f"udp://127.0.0.1:{free_udp_port()}"
    r = StreamReader(parse_stream_source(url), 64, 48, stall_timeout_s=0.5, open_timeout_s=0.5).start()
    with pytest.raises(VideoSourceError, match=rf"no video frame from '{url}' within 1 s"):
        r.wait_first(1.0)
