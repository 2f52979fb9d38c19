"""``aerodaas bench tello-video``: how to decode the Tello's H.264 UDP stream — PyAV vs OpenCV's FFmpeg backend.

The Tello emulator (:class:`aerodaas.emulators.tello.TelloEmulator`) streams rendered frames at the Tello's
960x720 @ 30 fps (configurable), each stamped with its index as a barcode (:func:`stamp_index`), so a decoded
frame's end-to-end latency is ``time decoded - time its first datagram was sent`` whatever frames were lost.

* **PyAV** (what :class:`aerodaas.backends.tello.TelloBackend` uses): our socket, frames reassembled by the
  Tello's "short datagram ends the frame" rule and decoded as one packet each (:class:`H264Reassembler`).
* **OpenCV**: ``cv2.VideoCapture("udp://...", cv2.CAP_FFMPEG)``, FFmpeg's own UDP input and demuxer, read in a
  thread as fast as frames come.

Reported per decoder: ``startup_s`` (stream on -> first frame), latency percentiles (ms), frames decoded vs sent,
and ``decode_ms`` — the CPU time to decode one frame to BGR, measured offline on the same recorded stream
(``av`` packet-wise; OpenCV reading the stream from a file), so it is free of network waiting.
"""
from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import tempfile
import threading
import time

from aerodaas.backends.tello.video import H264Reassembler
from aerodaas.bench.machine import machine_info
from aerodaas.bench.output import print_report
from aerodaas.emulators import free_udp_port
from aerodaas.emulators.tello import TelloEmulator, read_index

def _percentiles(xs: list[float]) -> dict:
    if not xs:
        return {"n": 0}
    xs = sorted(xs)
    q = lambda p: xs[min(len(xs) - 1, int(p * len(xs)))]  # noqa: E731
    return {"n": len(xs), "p50": round(q(0.5), 2), "p90": round(q(0.9), 2), "max": round(xs[-1], 2),
            "mean": round(statistics.fmean(xs), 2)}


def _stream(width: int, height: int, fps: float, video_port: int):
    """A started emulator streaming to ``video_port`` on loopback, and the client socket that asked for it."""
    emu = TelloEmulator(video_port=video_port, state_port=free_udp_port(), video_size=(width, height), video_fps=fps,
                        stamp_frame_index=True, camera_pitch_deg=30.0).start()
    cli = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    cli.settimeout(2.0)
    for cmd in ("command", "streamon"):
        cli.sendto(cmd.encode(), ("127.0.0.1", emu.command_port))
        cli.recv(64)
    return emu, cli


def run_pyav(width: int, height: int, fps: float, seconds: float, record: str | None = None) -> dict:
    """Live PyAV decode of the emulated stream; optionally writes the received bytes to ``record``."""
    port = free_udp_port()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    sock.bind(("127.0.0.1", port))
    sock.settimeout(0.2)
    dec = H264Reassembler()
    out = open(record, "wb") if record else None  # noqa: SIM115
    t_on = time.monotonic()
    emu, cli = _stream(width, height, fps, port)
    lat, first = [], None
    try:
        while time.monotonic() - t_on < seconds:
            try:
                data = sock.recv(65536)
            except socket.timeout:
                continue
            if out:
                out.write(data)
            for fr in dec.feed(data):
                now = time.monotonic()
                first = first or now
                sent = emu.send_times.get(read_index(fr))
                if sent is not None:
                    lat.append(1000.0 * (now - sent))
    finally:
        emu.stop()
        cli.close()
        sock.close()
        if out:
            out.close()
    return {"startup_s": round(first - t_on, 3) if first else None, "frames_sent": emu.frames_sent,
            "frames_decoded": dec.frames, "decode_errors": dec.errors, "latency_ms": _percentiles(lat),
            "live_decode_ms_per_frame": round(1000.0 * dec.decode_s / max(dec.frames, 1), 2)}


#: FFmpeg options for a low-latency live input (``OPENCV_FFMPEG_CAPTURE_OPTIONS`` syntax: ``key;value|...``)
LOW_DELAY = "fflags;nobuffer|flags;low_delay|probesize;32768|analyzeduration;0"


def run_opencv(width: int, height: int, fps: float, seconds: float, low_delay: bool = False) -> dict:
    """Live decode with ``cv2.VideoCapture(udp://..., CAP_FFMPEG)``; ``low_delay`` sets :data:`LOW_DELAY`
    (no input buffering, minimal probing) through ``OPENCV_FFMPEG_CAPTURE_OPTIONS`` (process-wide)."""
    import cv2  # lazy: heavy dependency (OpenCV)

    if low_delay:
        os.environ["OPENCV_FFMPEG_CAPTURE_OPTIONS"] = LOW_DELAY
    else:
        os.environ.pop("OPENCV_FFMPEG_CAPTURE_OPTIONS", None)

    port = free_udp_port()
    res: dict = {"opened": False}
    lat: list[float] = []
    emu_box: list = []
    t_on = time.monotonic()

    def reader() -> None:
        cap = cv2.VideoCapture(f"udp://127.0.0.1:{port}?overrun_nonfatal=1&fifo_size=50000000", cv2.CAP_FFMPEG)
        res["opened"] = bool(cap.isOpened())
        res["open_s"] = round(time.monotonic() - t_on, 3)
        n = 0
        while cap.isOpened() and time.monotonic() - t_on < seconds:
            ok, fr = cap.read()
            if not ok:
                break
            now = time.monotonic()
            res.setdefault("startup_s", round(now - t_on, 3))
            n += 1
            if emu_box:
                sent = emu_box[0].send_times.get(read_index(fr))
                if sent is not None:
                    lat.append(1000.0 * (now - sent))
        res["frames_decoded"] = n
        cap.release()

    th = threading.Thread(target=reader, daemon=True)
    th.start()  # FFmpeg opens (and probes) the UDP input itself: start listening before the stream starts
    time.sleep(0.2)
    emu, cli = _stream(width, height, fps, port)
    emu_box.append(emu)
    th.join(timeout=seconds + 30)
    emu.stop()
    cli.close()
    res["frames_sent"] = emu.frames_sent
    res["latency_ms"] = _percentiles(lat)
    return res


def offline_decode_ms(path: str) -> dict:
    """CPU ms per frame to decode the recorded stream at ``path`` to BGR, PyAV and OpenCV (the recording lost its
    datagram boundaries, so PyAV's parser cuts it into frames here; the cut is not timed)."""
    import av  # lazy: heavy dependency (PyAV)
    import cv2  # lazy: heavy dependency (OpenCV)

    with open(path, "rb") as f:
        packets = av.CodecContext.create("h264", "r").parse(f.read())
    dec = av.CodecContext.create("h264", "r")
    t0, n = time.process_time(), 0
    for p in packets:
        for fr in dec.decode(p):
            fr.to_ndarray(format="bgr24")
            n += 1
    pyav_ms = 1000.0 * (time.process_time() - t0) / max(n, 1)
    cap = cv2.VideoCapture(path, cv2.CAP_FFMPEG)
    t0, m = time.process_time(), 0
    while cap.read()[0]:
        m += 1
    cv_ms = 1000.0 * (time.process_time() - t0) / max(m, 1)
    cap.release()
    return {"frames": n, "pyav_ms": round(pyav_ms, 2), "opencv_frames": m, "opencv_ms": round(cv_ms, 2),
            "note": "process CPU time per frame incl. conversion to BGR (all decoder threads)"}


def run(width: int = 960, height: int = 720, fps: float = 30.0, seconds: float = 8.0) -> dict:
    with tempfile.TemporaryDirectory() as d:
        rec = os.path.join(d, "tello.h264")
        pyav = run_pyav(width, height, fps, seconds, record=rec)
        offline = offline_decode_ms(rec)
    ocv = run_opencv(width, height, fps, seconds)
    ocv_low = run_opencv(width, height, fps, seconds, low_delay=True)
    return {"machine": machine_info(), "stream": {"width": width, "height": height, "fps": fps, "seconds": seconds},
            "pyav": pyav, "opencv": ocv, "opencv_low_delay": ocv_low, "offline_decode": offline}


def main(args: argparse.Namespace) -> int:
    """``aerodaas bench tello-video``: the report of :func:`run` as JSON on standard output."""
    print_report(json.dumps(run(args.width, args.height, args.fps, args.seconds), indent=2))
    return 0
