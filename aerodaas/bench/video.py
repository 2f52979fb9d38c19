"""``aerodaas bench video``: glass-to-analytics latency and decode cost of a drone's video stream — our reader
(:class:`aerodaas.video.StreamReader`, taken when it wakes the consumer, as the camera takes it) against the loops a user would otherwise
write: a bare PyAV decode loop, OpenCV's ``VideoCapture(url, CAP_FFMPEG)`` with its default buffering, and a
GStreamer ``appsink`` pipeline (:mod:`aerodaas.bench.video_gst`, run under the system Python that has PyGObject).

A sender process encodes frames (a real aerial photo from $AERODAAS_DATA_DIR when there is one) with PyAV's
libx264 (ultrafast, zerolatency, a keyframe a second, no B-frames) and streams them as MPEG-TS on loopback UDP. Each
frame carries its index as an ArUco marker (OpenCV ``aruco``, DICT_4X4_1000) drawn before encoding; the sender logs
the monotonic time just before it encodes each one ("glass"). A reader decodes, finds the marker (in the
top-left corner only, the same cost for every reader) and counts ``latency = time the frame is in the consumer's
hands - its glass time`` (CLOCK_MONOTONIC is one clock for every process on the host). Per reader and resolution:
latency percentiles (ms), frames received vs sent, CPU per stream (% of one core: this process's CPU time over the
wall time, marker search included; for GStreamer its own process's CPU time is added) and CPU ms per frame. Each reader gets a fresh sender: nothing carries over.
"""
from __future__ import annotations

import argparse
import json
import os
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from aerodaas.bench.machine import machine_info
from aerodaas.bench.options import VIDEO_READERS, VIDEO_SIZES
from aerodaas.bench.output import print_report
from aerodaas.bench.progress import bench_progress
from aerodaas.bench.tello_video import _percentiles
from aerodaas.bench.video_gst import HEADER
from aerodaas.emulators import free_udp_port
from aerodaas.video import StreamReader, parse_stream_source

#: the ArUco dictionary and the marker's size (px) and position (top-left corner, margin px)
ARUCO_DICT = "DICT_4X4_1000"
MARKER_PX, MARGIN_PX = 160, 16
READERS = VIDEO_READERS
#: the interpreter that runs the GStreamer peer: one with PyGObject (Debian's python3-gi is for /usr/bin/python3)
GST_PYTHON = os.environ.get("AERODAAS_GST_PYTHON", "/usr/bin/python3")
#: the square of pixels (top-left) that holds the marker: what every reader searches
ROI_PX = MARKER_PX + 3 * MARGIN_PX
SIZES = VIDEO_SIZES


def _aruco():
    import cv2  # lazy: heavy dependency (OpenCV)

    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICT))
    return d, cv2.aruco.ArucoDetector(d, cv2.aruco.DetectorParameters())


def send(url: str, width: int, height: int, fps: float, log_path: str) -> None:
    """The sender (run in its own process): frames with their index as an ArUco marker, MPEG-TS to ``url``, in
    real time until killed; writes ``index glass_time`` lines to ``log_path``."""
    import av  # lazy: heavy dependency (PyAV)
    import cv2  # lazy: heavy dependency (OpenCV)

    d, _ = _aruco()
    photo = None
    data = os.environ.get("AERODAAS_DATA_DIR")
    if data:
        photo = cv2.imread(str(Path(data) / "imagery" / "brighton_beach" / "DJI_0031.JPG"))
    base = cv2.resize(photo, (width, height), interpolation=cv2.INTER_AREA) if photo is not None else \
        np.tile(np.linspace(40, 200, width, dtype=np.uint8)[None, :, None], (height, 1, 3))
    out = av.open(url + "?pkt_size=1316", "w", format="mpegts")
    st = out.add_stream("libx264", rate=int(round(fps)))
    st.width, st.height, st.pix_fmt = width, height, "yuv420p"
    st.options = {"g": str(int(round(fps))), "bf": "0", "tune": "zerolatency", "preset": "ultrafast"}
    log = open(log_path, "w", buffering=1)
    t0, i = time.monotonic(), 0
    while True:
        img = base.copy()
        m = cv2.aruco.generateImageMarker(d, i % 1000, MARKER_PX)
        img[MARGIN_PX:MARGIN_PX + MARKER_PX, MARGIN_PX:MARGIN_PX + MARKER_PX] = m[:, :, None]
        glass = time.monotonic()
        vf = av.VideoFrame.from_ndarray(img, format="bgr24")
        vf.pts = i
        for p in st.encode(vf):
            out.mux(p)
        log.write(f"{i} {glass:.6f}\n")
        i += 1
        delay = t0 + i / fps - time.monotonic()
        if delay > 0:
            time.sleep(delay)


class _Marker:
    """Reads a frame's index from its marker (None when not found); unwraps the 1000-id dictionary."""

    def __init__(self) -> None:
        self.detector = _aruco()[1]
        self.last = -1

    def index(self, img) -> int | None:
        roi = img[:ROI_PX, :ROI_PX]
        _, ids, _ = self.detector.detectMarkers(roi)
        if ids is None or len(ids) != 1:
            return None
        k = int(ids[0][0])
        base = max(self.last, 0) // 1000 * 1000
        idx = base + k
        if idx < self.last - 500:
            idx += 1000
        self.last = max(self.last, idx)
        return idx


def _read(reader: str, url: str, width: int, height: int, fps: float,
          seconds: float) -> tuple[list[tuple[int, float]], dict]:
    """Run one reader for ``seconds``: ([(frame index, time in the consumer's hands)], facts of the reader: for
    GStreamer the decoder it chose and its process's CPU seconds)."""
    marker = _Marker()
    got: list[tuple[int, float]] = []
    end = time.monotonic() + 60.0  # the first frame within a minute; then ``seconds`` of reading from it

    def note(img, t: float | None = None) -> None:
        nonlocal end
        t = time.monotonic() if t is None else t
        idx = marker.index(img)
        if idx is not None:
            if not got:
                end = t + seconds
            got.append((idx, t))

    if reader == "gstreamer":
        return got, _read_gstreamer(url, seconds, note)
    if reader == "ours":
        arrived = threading.Event()
        r = StreamReader(parse_stream_source(url), width, height, on_frame=arrived.set).start()
        try:
            r.wait_first(30.0)
            while time.monotonic() < end:  # the camera's hand-off: woken by the reader when a frame arrives
                arrived.wait(0.5 / fps)  # (the camera's clock also ticks at twice the stream's rate)
                arrived.clear()
                f = r.take()
                if f is not None:
                    note(f.image)
        finally:
            r.close()
    elif reader == "pyav":
        import av  # lazy: heavy dependency (PyAV)

        c = av.open(url + "?overrun_nonfatal=1&fifo_size=1000000&buffer_size=4194304", format="mpegts",
                    options={"fflags": "nobuffer"}, timeout=(30.0, 5.0))
        try:
            for frame in c.decode(video=0):
                note(frame.to_ndarray(format="bgr24"))
                if time.monotonic() >= end:
                    break
        finally:
            c.close()
    else:
        import cv2  # lazy: heavy dependency (OpenCV)

        cap = cv2.VideoCapture(url, cv2.CAP_FFMPEG)
        try:
            while time.monotonic() < end:
                ok, img = cap.read()
                if ok:
                    note(img)
                elif not cap.isOpened():
                    break
        finally:
            cap.release()
    return got, {}


def _read_gstreamer(url: str, seconds: float, note) -> dict:
    """The GStreamer appsink peer: :mod:`aerodaas.bench.video_gst` in a process of :data:`GST_PYTHON`, whose records
    (arrival time taken at the pull, the marker's corner of the frame) are searched here like every reader's frames.

    :raises RuntimeError: the system Python has no PyGObject/GStreamer (it names the packages), or the peer failed
    """
    port = url.rsplit(":", 1)[1]
    script = str(Path(__file__).with_name("video_gst.py"))
    proc = subprocess.Popen([GST_PYTHON, script, port, str(seconds), str(ROI_PX)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    try:  # room for several records (130 kB each): the peer must not wait on our marker search between pulls
        import fcntl  # lazy: optional dependency (fcntl is POSIX only)

        fcntl.fcntl(proc.stdout.fileno(), fcntl.F_SETPIPE_SZ, 1 << 20)
    except (ImportError, AttributeError, OSError):
        pass
    try:
        while True:
            head = proc.stdout.read(HEADER.size)
            if len(head) < HEADER.size:
                break
            t, w, h = HEADER.unpack(head)
            rows, cols = min(ROI_PX, h), min(ROI_PX, w)
            body = proc.stdout.read(rows * ROI_PX * 3)
            if len(body) < rows * ROI_PX * 3:
                break
            img = np.frombuffer(body, np.uint8).reshape(rows, ROI_PX, 3)[:, :cols]
            note(img, t)
        err = proc.stderr.read().decode(errors="replace")
    finally:
        proc.kill()
        proc.wait(timeout=30)
    facts = None
    for line in reversed(err.splitlines()):
        try:
            facts = json.loads(line)
            break
        except (ValueError, struct.error):
            continue
    if proc.returncode not in (0, -9) or facts is None:
        raise RuntimeError(f"the GStreamer peer ({GST_PYTHON} {script}) failed: it needs PyGObject and GStreamer's "
                           f"base/good/bad plug-ins (Debian python3-gi, gstreamer1.0-plugins-*; "
                           f"sh tests/install-rig.sh installs them): {err[-800:]}")
    return facts


def run_one(reader: str, size: str, fps: float, seconds: float) -> dict:
    """One reader on one fresh stream: latency percentiles (ms), frames, CPU."""
    width, height = SIZES[size]
    url = f"udp://127.0.0.1:{free_udp_port()}"
    with tempfile.TemporaryDirectory() as tmp:
        log = os.path.join(tmp, "glass.log")
        proc = subprocess.Popen([sys.executable, "-c", "import sys; from aerodaas.bench.video import send; "
                                 "send(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), sys.argv[5])",
                                 url, str(width), str(height), str(fps), log], env=dict(os.environ))
        try:
            cpu0, wall0 = time.process_time(), time.monotonic()
            got, facts = _read(reader, url, width, height, fps, seconds)
            cpu, wall = time.process_time() - cpu0 + facts.get("cpu_s", 0.0), time.monotonic() - wall0
        finally:
            proc.kill()
            proc.wait(timeout=30)
        glass = {}
        for line in Path(log).read_text().splitlines():
            i, t = line.split()
            glass[int(i)] = float(t)
    lat = [(t - glass[i]) * 1e3 for i, t in got if i in glass]
    first = min((i for i, _ in got), default=None)
    sent = sum(1 for i in glass if first is not None and i >= first and glass[i] <= (got[-1][1] if got else 0))
    p = _percentiles(lat)
    if lat:
        s = sorted(lat)
        p["p99"] = round(s[min(len(s) - 1, int(0.99 * len(s)))], 2)
    return {"reader": reader, "size": size, "fps": fps, "seconds": seconds, "latency_ms": p,
            **({"decoder": facts["decoder"]} if "decoder" in facts else {}),
            "frames_received": len(got), "frames_sent_meanwhile": sent,
            "cpu_percent_of_one_core": round(100.0 * cpu / wall, 1) if wall else None,
            "cpu_ms_per_frame": round(1e3 * cpu / len(got), 2) if got else None}


def main(args: argparse.Namespace) -> int:
    readers = args.readers.split(",")
    bad = [r for r in readers if r not in READERS]
    sizes = args.sizes.split(",")
    bad += [s for s in sizes if s not in SIZES]
    if bad or args.seconds <= 0 or not 1 <= args.fps <= 120:
        print(f"aerodaas bench video: unknown reader/size {bad} (readers {list(READERS)}, sizes {list(SIZES)}), "
              f"or --seconds/--fps out of range", file=sys.stderr)
        return 2
    report = {"benchmark": "video", "machine": machine_info(), "transport": "MPEG-TS over loopback UDP",
              "encoder": "libx264 ultrafast zerolatency, g=fps, no B-frames", "marker": ARUCO_DICT, "runs": []}
    with bench_progress("bench video", total=len(readers) * len(sizes)) as (progress, task):
        for size in sizes:
            for r in readers:
                res = run_one(r, size, args.fps, args.seconds)
                report["runs"].append(res)
                progress.console.print(f"{size} {r}: latency {res['latency_ms']}, {res['frames_received']} of "
                                       f"{res['frames_sent_meanwhile']} frames, cpu {res['cpu_percent_of_one_core']} %")
                progress.advance(task)
    report["load_avg_1min_after"] = round(os.getloadavg()[0], 2)
    text = json.dumps(report, indent=2)
    if args.out:
        Path(args.out).write_text(text)

    print_report(text)
    return 0
