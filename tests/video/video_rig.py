"""Test rig for video sources: real aerial footage made from $AERODAAS_DATA_DIR imagery, and a sender process that
streams it the way a drone's video link does (MPEG-TS on UDP, or raw RTP H.264/H.265 as QGroundControl receives on
UDP 5600), encoded with PyAV's bundled libx264 (libx265 for H.265). Run as a script it is the sender:

    python tests/video/video_rig.py FILE.mp4 udp://127.0.0.1:PORT      # MPEG-TS
    python tests/video/video_rig.py FILE.mp4 rtp://127.0.0.1:PORT      # RTP H.264 (in-band SPS/PPS on every keyframe)
    python tests/video/video_rig.py FILE.mp4 rtp://127.0.0.1:PORT h265 # RTP H.265 (in-band VPS/SPS/PPS)
    python tests/video/video_rig.py rtsp FILE.mp4 PORT TS_PORT         # GStreamer's RTSP server, rtsp://127.0.0.1:PORT/cam

It plays the file at its frame rate in a loop until killed; a frame counter is not drawn (the footage is real)."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

DEFAULT_IMAGE = "imagery/brighton_beach/DJI_0031.JPG"
EMPTY_IMAGE = "imagery/brighton_beach/DJI_0025.JPG"


def make_footage(out: Path, *, seconds: float = 8.0, empty_s: float = 0.0, fps: int = 10,
                 size: tuple[int, int] = (640, 480), image: str = DEFAULT_IMAGE, gop: int = 10,
                 pan: tuple[float, float, float] = (0.333, 0.5, 0.278), empty_image: str = EMPTY_IMAGE) -> Path:
    """Write an H.264 MP4 (``size`` px, ``fps``) of real aerial photos from $AERODAAS_DATA_DIR: ``seconds`` of a
    slow pan over parked cars (its left edge from ``pan[0]`` to ``pan[1]`` of the photo's width and back, its top at
    ``pan[2]`` of its height: the default passes over the cars of DJI_0031, which YOLOX-Nano finds in every
    position at scores 0.34-0.61), then ``empty_s`` seconds over ground with no vehicle (DJI_0025's lawn: none
    found anywhere in it), so that a follow ends and the survey resumes. Raises FileNotFoundError when a photo is
    missing."""
    import av
    import cv2

    def load(name: str) -> np.ndarray:
        src = Path(os.environ.get("AERODAAS_DATA_DIR", "")) / name
        photo = cv2.imread(str(src))
        if photo is None:
            raise FileNotFoundError(f"aerial photo {src} not found (set AERODAAS_DATA_DIR)")
        return photo

    photo, empty = load(image), load(empty_image) if empty_s > 0 else None
    w, h = size
    crop_w = photo.shape[1] // 3  # about 25 m of ground across: a car is ~120 px long, as from 16 m up
    crop_h = crop_w * h // w
    n, n_empty = int(seconds * fps), int(empty_s * fps)
    x0, x1, y = int(pan[0] * photo.shape[1]), int(pan[1] * photo.shape[1]), int(pan[2] * photo.shape[0])
    with av.open(str(out), "w") as c:
        s = c.add_stream("libx264", rate=fps)
        s.width, s.height, s.pix_fmt = w, h, "yuv420p"
        s.options = {"g": str(gop), "bf": "0", "tune": "zerolatency", "preset": "ultrafast"}
        for i in range(n + n_empty):
            if i < n:
                a = 1.0 - abs(2.0 * i / max(n - 1, 1) - 1.0)  # 0 -> 1 -> 0
                x = min(int(x0 + (x1 - x0) * a), photo.shape[1] - crop_w)
                crop = photo[min(y, photo.shape[0] - crop_h):][:crop_h, x:x + crop_w]
            else:
                x = int((empty.shape[1] - crop_w) * (i - n) / max(n_empty, 1))
                crop = empty[:crop_h, x:x + crop_w]
            frame = cv2.resize(crop, (w, h), interpolation=cv2.INTER_AREA)
            for p in s.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="bgr24")):
                c.mux(p)
        for p in s.encode():
            c.mux(p)
    return out


#: the app's limits for a stream run whose flight is not under test (apps/vehicle_tracking.json: 3 m/s, 1.5 m/s up,
#: 2 m/s2): twice each, so its take-off and survey legs take about half the wall time at speed-up 1, the stream's
#: clock; the pose-tag tolerance grows with the speed (:func:`check_pose_tags`), the landing is the vehicle's own
QUICK_LIMITS = {"max_speed": 6.0, "max_vertical_speed": 3.0, "max_acceleration": 4.0}


#: the sender's codecs: PyAV's encoder and its options for a one-second GOP, no B-frames and the parameter sets
#: (SPS/PPS, and VPS for H.265) repeated on every keyframe, so that a receiver joining mid-stream decodes
SENDER_CODECS = {
    "h264": ("libx264", lambda gop: {"g": str(gop), "bf": "0", "tune": "zerolatency", "preset": "ultrafast",
                                     "x264-params": "repeat-headers=1"}),
    "h265": ("libx265", lambda gop: {"preset": "ultrafast", "tune": "zerolatency",
                                     "x265-params": f"keyint={gop}:bframes=0:repeat-headers=1:log-level=error"}),
}


def send(path: str, url: str, codec: str = "h264") -> None:
    """Stream ``path`` to ``url`` (udp:// as MPEG-TS, rtp:// as raw RTP, RFC 6184 / RFC 7798) encoded with
    ``codec`` (a key of :data:`SENDER_CODECS`) in real time, looping, until killed. Raises KeyError for another
    codec."""
    import av

    encoder, options = SENDER_CODECS[codec]
    fmt = "rtp" if url.startswith("rtp://") else "mpegts"
    out = av.open(url + ("?pkt_size=1200" if fmt == "rtp" else "?pkt_size=1316"), "w", format=fmt)
    src = av.open(path)
    ist = src.streams.video[0]
    fps = float(ist.average_rate or 10)
    st = out.add_stream(encoder, rate=int(round(fps)))
    st.width, st.height, st.pix_fmt = ist.codec_context.width, ist.codec_context.height, "yuv420p"
    st.options = options(int(round(fps)))
    t0, i = time.monotonic(), 0
    while True:
        for f in src.decode(ist):
            vf = av.VideoFrame.from_ndarray(f.to_ndarray(format="bgr24"), format="bgr24")
            vf.pts = i
            for p in st.encode(vf):
                out.mux(p)
            i += 1
            delay = t0 + i / fps - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        src.seek(0)


def _kill(proc: "subprocess.Popen | None") -> None:
    """Kill ``proc`` (if any) and reap it; returns None (the caller's new handle)."""
    if proc is not None:
        proc.kill()
        proc.wait(timeout=30)
    return None


class Sender:
    """A sender subprocess (this file run as a script) of ``path`` to ``url`` encoded with ``codec`` (``h264`` or
    ``h265``); :meth:`stop` kills it (a link outage), :meth:`start` starts it again."""

    def __init__(self, path: Path, url: str, codec: str = "h264") -> None:
        if codec not in SENDER_CODECS:
            raise ValueError(f"sender codec must be one of {sorted(SENDER_CODECS)}, got {codec!r}")
        self.path, self.url, self.codec, self.proc = str(path), url, codec, None

    def start(self) -> "Sender":
        self.proc = subprocess.Popen([sys.executable, __file__, self.path, self.url, self.codec],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return self

    def stop(self) -> None:
        self.proc = _kill(self.proc)

    stop_all = stop


class RtspServer:
    """GStreamer's RTSP server (tests/video/rtsp_server.py, run by /usr/bin/python3 with PyGObject from Debian's
    python3-gi) serving ``rtsp://127.0.0.1:PORT/cam`` relayed from a looping MPEG-TS :class:`Sender`.
    :meth:`stop` kills the server only (an RTSP outage: the TCP session drops); :meth:`start` brings it back.
    Raises AssertionError naming the missing Debian packages when it cannot start: in CI the test fails."""

    PACKAGES = "gstreamer1.0-rtsp gir1.2-gst-rtsp-server-1.0 python3-gi gstreamer1.0-plugins-{base,good,bad}"

    def __init__(self, footage: Path, port: int | None = None, ts_port: int | None = None) -> None:
        self.port, self.ts_port = port or free_tcp_port(), ts_port or free_udp_port()
        self.url = f"rtsp://127.0.0.1:{self.port}/cam"
        self.sender = Sender(footage, f"udp://127.0.0.1:{self.ts_port}")
        self.proc = None

    def start(self) -> "RtspServer":
        if self.sender.proc is None:
            self.sender.start()
        self.proc = subprocess.Popen(["/usr/bin/python3", str(Path(__file__).with_name("rtsp_server.py")),
                                      str(self.port), str(self.ts_port)], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        if line.strip() != "ready":
            err = self.proc.stderr.read()[-2000:]
            self.stop_all()
            raise AssertionError(f"the GStreamer RTSP server did not start (install the Debian packages "
                                 f"{self.PACKAGES}, as the README's test command does): {err}")
        return self

    def stop(self) -> None:
        self.proc = _kill(self.proc)

    def stop_all(self) -> None:
        self.stop()
        self.sender.stop()


def check_stream_recording(rec: Path, robot: str = "quadrotor_base", camera: str = "cam1") -> dict:
    """Read a run's recording of a stream camera and assert what every stream run must hold: every frame taken from
    the stream recorded, but the ones refused before they left the camera's actor (``not_recorded``) or by the
    recorder actor's full queue (``/run/recorder_drops``), each counted; every decoded frame
    taken, replaced or still waiting, and each frame's pose tag the vehicle's pose at its capture time
    (:func:`check_pose_tags`: from the vehicle samples around the capture, and where the recording's own odometry says the
    vehicle was then). Returns ``{"stats", "timing", "follow" (log times of the follow analytics' navigation),
    "odometry" ([(log time, message)]), "poses" (what check_pose_tags judged)}`` for the test's own assertions."""
    from aerodaas.recording.reader import read_messages

    topic = f"/{robot}/camera/{camera}"
    images, timing, stats, follow, odometry, drops = 0, [], None, [], [], None
    for tp, schema, t, msg in read_messages(str(rec)):
        if tp == "/run/recorder_drops":
            drops = msg
        elif tp == topic and schema == "foxglove.CompressedImage":
            images += 1
        elif tp == f"/{robot}/follow/navigation":
            follow.append(t)
        elif tp == f"{topic}/timing":
            timing.append(msg)
        elif tp == f"{topic}/video_stats":
            stats = msg
        elif tp == f"/{robot}/odometry":
            odometry.append((t, msg))
    assert stats is not None and stats["taken"] > 0, stats
    assert drops is not None, "the recording has no /run/recorder_drops"
    at_recorder = drops["frames_dropped"].get(topic, 0)  # refused by the recorder actor's full queue, counted there
    assert images == stats["taken"] - stats["not_recorded"] - at_recorder and len(timing) == stats["taken"], \
        (images, stats, drops)
    assert stats["decoded"] == stats["taken"] + stats["overwritten"] + stats["waiting"], stats
    assert all(m["capture_t"] <= m["arrival_t"] for m in timing)
    poses = check_pose_tags(timing, [m for _, m in odometry])
    return {"stats": stats, "timing": timing, "follow": follow, "odometry": odometry, "poses": poses}


#: a pose tag from one sample (the capture outside the camera's samples) must be of a sample this near, s
POSE_SAMPLE_SLACK_S = 0.1
#: ... and when that sample is older than the capture (the vehicle sent no newer one within the camera's
#: POSE_WAIT_S), no older than the odometry's largest sample gap around the capture plus this, s
AFTER_NEWEST_SLACK_S = 1e-3
#: added to the fastest speed the odometry shows: the speed between two samples can exceed the sampled ones
#: (a quadrotor gains well under 1 m/s in the 0.05 s to the nearest 10 Hz sample), m/s
SPEED_SLACK_MPS = 1.0
#: added to every position tolerance: rounding of the recorded numbers, m
POSITION_SLACK_M = 0.2
#: how far around a frame's samples the odometry's largest sample gap is looked for, s
GAP_WINDOW_S = 2.0


def check_pose_tags(timing: list[dict], odometry: list[dict], settle_s: float = 1.0) -> dict:
    """Assert that each stream frame's pose tag (``timing``: the ``aerodaas.FrameTiming`` messages) is the vehicle's
    pose at the frame's capture, from what the recording holds; for frames arriving ``settle_s`` (s) after the first
    one (the camera then has a second of per-tick poses behind it):

    1. the vehicle's position samples it was interpolated between (``pose_samples_t``: their own times) enclose ``capture_t``, or the one sample used outside them is within :data:`POSE_SAMPLE_SLACK_S`
       after it, or older than it by no more than the vehicle's own largest sample gap there (a stalled stream of
       samples) plus :data:`AFTER_NEWEST_SLACK_S`, or older by any amount when the frame's ``pose_wait_s`` says the
       camera waited its full :data:`~aerodaas.actors.sensors.camera.POSE_WAIT_S` for a newer one (samples that
       reached it late on a loaded machine, a delay the recording does not show: its position is still judged by 2):
       a pose taken at the arrival (20-300 ms later) is bracketed by later samples;
    2. its ``position`` (ENU m) agrees with the recording's own ``odometry`` (the ``/<robot>/odometry`` messages:
       ``t`` s, ``position``, ``velocity``) interpolated at ``capture_t``, for every frame the odometry surrounds.

    The tolerance of 2 is made of speed x sample gap only, never of a wall-clock time: both come from the same
    vehicle samples stamped with the same times, so they differ by (a) the camera's own interpolation between its
    samples, at most speed x their gap; (b) the odometry's interpolation, at most speed x its gap around
    ``capture_t`` (the recording keeps samples at the odometry rate, the camera every sample its ticks saw); and,
    for a pose held from an older sample only, (c) that sample's age at the capture. Speed: the fastest the odometry shows anywhere (sampled
    velocity and distance over sample gaps) plus :data:`SPEED_SLACK_MPS`. A loaded machine delays ticks and samples,
    which widens the gaps and so the tolerance with them: it cannot break the check; a pose taken at arrival
    instead of capture can (tests/video/test_video_source.py fabricates one). Raises AssertionError naming the frame, or
    when no frame's tag could be compared with the odometry (none inside its time span: a check of zero poses).
    Returns ``{"judged": frames judged by 1, "held": of them, poses held after the camera's full wait, "compared":
    frames judged by 2, "worst_m": largest position error, "worst_ratio": largest error / tolerance}``."""
    from aerodaas.actors.sensors.camera import POSE_WAIT_S

    assert timing, "no frame timing recorded"
    unwaited = [m["seq"] for m in timing if "pose_wait_s" not in m]
    assert not unwaited, f"frames without the camera's pose_wait_s: {unwaited[:10]}"
    t_first = timing[0]["arrival_t"]
    late = [m for m in timing if m["arrival_t"] > t_first + settle_s]
    assert late, "no frame arrived a second after the first: no pose tag to judge"
    odo = sorted((float(o["t"]), np.asarray(o["position"], float), np.asarray(o.get("velocity") or (0, 0, 0), float))
                 for o in odometry)
    times = np.array([o[0] for o in odo])
    gaps = np.diff(times) if len(odo) >= 2 else np.zeros(0)

    def stall_near(t: float) -> float:
        """The odometry's largest sample gap within GAP_WINDOW_S of run time ``t`` (s)."""
        near = slice(max(int(np.searchsorted(times, t - GAP_WINDOW_S)) - 1, 0),
                     int(np.searchsorted(times, t + GAP_WINDOW_S)))
        return float(np.max(gaps[near], initial=0.0))

    held = 0
    for m in late:
        samples, c = m["pose_samples_t"], m["capture_t"]
        waited = len(samples) == 1 and samples[0] < c and m["pose_wait_s"] >= POSE_WAIT_S
        held += waited
        assert samples and (samples[0] <= c <= samples[-1] if len(samples) == 2 else waited
                            or -stall_near(c) - AFTER_NEWEST_SLACK_S <= samples[0] - c <= POSE_SAMPLE_SLACK_S), \
            (f"frame {m['seq']}: pose from the samples at {samples} s, captured at {c} s (arrived at {m['arrival_t']} "
             f"s, waited {m['pose_wait_s']} s for a newer sample)")
    compared, worst_m, worst_ratio = 0, 0.0, 0.0
    if len(odo) >= 2:
        chord = [float(np.linalg.norm(b[1] - a[1])) / g for a, b, g in zip(odo, odo[1:], gaps) if g > 0]
        speed = max([float(np.linalg.norm(o[2])) for o in odo] + chord) + SPEED_SLACK_MPS
        for m in late:
            c = m["capture_t"]
            if not times[0] <= c <= times[-1]:
                continue  # before the odometry's first sample or after its last: nothing to compare with
            hi = min(int(np.searchsorted(times, c, side="right")), len(odo) - 1)
            lo = hi - 1
            a = (c - times[lo]) / (times[hi] - times[lo]) if times[hi] > times[lo] else 0.0
            expected = odo[lo][1] + a * (odo[hi][1] - odo[lo][1])
            samples = list(m["pose_samples_t"]) + [c]
            tol = speed * ((max(samples) - min(samples)) + (times[hi] - times[lo])) + POSITION_SLACK_M
            err = float(np.linalg.norm(np.asarray(m["position"], float) - expected))
            assert err <= tol, (f"frame {m['seq']} captured at {c:.3f} s: pose tag {m['position']} is {err:.2f} m "
                                f"from the odometry there {expected.round(2).tolist()} (tolerance {tol:.2f} m: "
                                f"{speed:.1f} m/s x gaps); arrived at {m['arrival_t']:.3f} s")
            compared += 1
            worst_m, worst_ratio = max(worst_m, err), max(worst_ratio, err / float(tol))
    assert compared >= 1, (f"no pose tag was compared with the odometry ({len(late)} frames judged by their ticks, "
                           f"{len(odo)} odometry samples): a check of zero poses cannot fail")
    return {"judged": len(late), "held": held, "compared": compared, "worst_m": worst_m, "worst_ratio": worst_ratio}


def free_tcp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve_rtsp(footage: str, port: int, ts_port: int) -> None:
    """:class:`RtspServer` on ``port`` (its MPEG-TS relay on UDP ``ts_port``) until this process is killed (then
    both children die with it: they are in its process group, which whoever started it kills)."""
    server = RtspServer(Path(footage), port, ts_port).start()
    try:
        while server.proc.poll() is None:
            time.sleep(0.5)
    finally:
        server.stop_all()


if __name__ == "__main__":
    if sys.argv[1] == "rtsp":  # rtsp FOOTAGE PORT TS_PORT: a GStreamer RTSP server (tests/firmware/test_sitl_video.py)
        serve_rtsp(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
    else:  # FOOTAGE URL [CODEC]: a sender
        send(sys.argv[1], sys.argv[2], *sys.argv[3:4])
