"""The GStreamer peer of ``aerodaas bench video``: the ``appsink`` pipeline a user writes to read a drone's
MPEG-TS/UDP stream with GStreamer, run as its own process under the system Python that has PyGObject
(Debian ``python3-gi``; the project's interpreter usually has none).

    /usr/bin/python3 aerodaas/bench/video_gst.py URL_PORT SECONDS ROI_PX

Pipeline (the low-latency form GStreamer's docs and Q&A give for appsink: no clock sync, one buffer, drop old)::

    udpsrc port=P caps=video/mpegts ! tsdemux ! h264parse ! decodebin ! videoconvert ! video/x-raw,format=BGR
      ! appsink sync=false max-buffers=1 drop=true

``decodebin`` picks ``avdec_h264`` (Debian ``gstreamer1.0-libav``) when it is installed, else ``openh264dec``; the
element it chose is reported. For each frame pulled the script takes ``time.monotonic()`` (CLOCK_MONOTONIC, the
sender's clock too) at once, then writes a record to stdout: a 16-byte header (``<d`` arrival time in seconds,
``<I`` width, ``<I`` height) and the top-left ``ROI_PX`` x ``ROI_PX`` BGR pixels (where the sender draws its ArUco
marker), so the parent finds the marker with the same OpenCV code as every other reader. This file imports nothing
of AeroDaaS and needs only PyGObject with GStreamer 1.x. At the end it writes one JSON line to stderr: the decoder
chosen and this process's CPU seconds from its first frame on (GStreamer's start-up, a plug-in registry scan paid
once per application, is left out).
"""
import json
import os
import struct
import sys
import time

HEADER = struct.Struct("<dII")


def main() -> int:
    import gi  # lazy: optional dependency (GStreamer bindings; the project interpreter imports HEADER without them)

    gi.require_version("Gst", "1.0")
    from gi.repository import Gst  # lazy: optional dependency (GStreamer bindings)

    port, seconds, roi = int(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
    Gst.init(None)
    pipe = Gst.parse_launch(
        f'udpsrc port={port} buffer-size=4194304 caps="video/mpegts,systemstream=(boolean)true" ! tsdemux ! '
        f"h264parse ! decodebin name=dec ! videoconvert ! video/x-raw,format=BGR ! "
        f"appsink name=sink sync=false max-buffers=1 drop=true emit-signals=false")
    sink = pipe.get_by_name("sink")
    pipe.set_state(Gst.State.PLAYING)
    out = sys.stdout.buffer
    end = time.monotonic() + 60.0  # the first frame within a minute, then ``seconds`` from it
    first, cpu0 = True, os.times()
    try:
        while time.monotonic() < end:
            sample = sink.emit("try-pull-sample", Gst.SECOND)
            if sample is None:
                continue
            t = time.monotonic()
            if first:  # CPU from here on: GStreamer's start (plug-in registry scan) is paid once per application
                end, first, cpu0 = t + seconds, False, os.times()
            s = sample.get_caps().get_structure(0)
            w, h = s.get_value("width"), s.get_value("height")
            buf = sample.get_buffer()
            ok, info = buf.map(Gst.MapFlags.READ)
            if not ok:
                continue
            try:
                stride = (w * 3 + 3) & ~3  # GStreamer's default row alignment for packed RGB: 4 bytes
                rows = b"".join(info.data[r * stride:r * stride + roi * 3] for r in range(min(roi, h)))
            finally:
                buf.unmap(info)
            out.write(HEADER.pack(t, w, h) + rows)
            out.flush()
    finally:
        decoders: list = []
        pipe.get_by_name("dec").iterate_elements().foreach(
            lambda e: decoders.append(e.get_factory().get_name())
            if "Decoder" in (e.get_factory().get_metadata("klass") or "") else None)
        pipe.set_state(Gst.State.NULL)
        cpu = os.times()
        sys.stderr.write(json.dumps({"decoder": decoders[0] if decoders else None,
                                     "cpu_s": cpu.user + cpu.system - cpu0.user - cpu0.system}) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
