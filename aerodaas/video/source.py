"""What a camera's ``source`` names when it is a video stream, checked before Ray starts.

A drone's camera reaches the ground the way ground stations read it: an RTSP URL (gimbal cameras such as Siyi or
Herelink, a companion computer's MediaMTX / gst-rtsp-server), RTP H.264/H.265 on UDP 5600 (QGroundControl's
default video port, usually without an SDP file), MPEG-TS on UDP, a V4L2 device on the companion computer, or a video
file (looped: for tests and demonstrations). :func:`parse_stream_source` turns the ``source`` string and the
camera's stream properties into a :class:`StreamSpec` that FFmpeg (through PyAV) opens, or raises ValueError naming
the property and the value. Nothing here touches the network or imports PyAV.

Sources: FFmpeg's protocol documentation (``rtsp_transport``, ``protocol_whitelist``, the ``sdp`` demuxer);
RFC 4566 (SDP), RFC 6184 (RTP payload for H.264), RFC 7798 (H.265); QGroundControl's default UDP video port 5600
(``VideoSettings.udpUrl`` "0.0.0.0:5600").
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal
from urllib.parse import urlsplit

#: the built-in camera sources that are not video streams
NON_STREAM_SOURCES = ("sim", "backend", "mcap")
#: RTP video codecs FFmpeg depacketises from an SDP description (RFC 6184, RFC 7798)
RTP_CODECS = {"h264": "H264", "h265": "H265"}
#: file name endings read as video files
VIDEO_FILE_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi", ".ts", ".m2ts", ".h264", ".264", ".h265", ".265", ".hevc",
                       ".webm")
#: the dynamic RTP payload type senders use for H.264/H.265 (QGC, GStreamer's rtph264pay default: 96)
DEFAULT_PAYLOAD_TYPE = 96

StreamKind = Literal["rtsp", "rtp", "mpegts_udp", "mpegts_tcp", "sdp", "v4l2", "file"]


@dataclass(frozen=True)
class StreamSpec:
    """A checked video source. ``kind``: rtsp, rtp (raw RTP on UDP, described by an SDP we write), mpegts_udp,
    mpegts_tcp (MPEG-TS from a TCP server, as a MAVLink camera announces VIDEO_STREAM_TYPE_TCP_MPEG), sdp
    (the sender's SDP file), v4l2, file. ``url``: what FFmpeg opens (for rtp: None until :meth:`sdp_text` is
    written to a file); ``format``: FFmpeg demuxer name or None (probe); ``options``: FFmpeg AVOptions;
    ``live``: a stream that can stop (reopened with backoff) as opposed to a file (looped at EOF);
    ``host``/``port``/``codec``/``payload_type``: for kind rtp."""

    kind: StreamKind
    source: str
    url: str | None
    format: str | None = None
    options: dict[str, str] = field(default_factory=dict)
    live: bool = True
    host: str = "0.0.0.0"
    port: int = 0
    codec: str = "h264"
    payload_type: int = DEFAULT_PAYLOAD_TYPE

    def sdp_text(self) -> str:
        """For kind rtp: the SDP (RFC 4566) describing the stream, as QGroundControl builds for UDP 5600: one video
        medium at ``port`` with a dynamic payload type and a 90 kHz clock (RFC 6184 §8.2.1)."""
        enc = RTP_CODECS[self.codec]
        return ("v=0\r\no=- 0 0 IN IP4 127.0.0.1\r\ns=AeroDaaS camera\r\n"
                f"c=IN IP4 {self.host}\r\nt=0 0\r\nm=video {self.port} RTP/AVP {self.payload_type}\r\n"
                f"a=rtpmap:{self.payload_type} {enc}/90000\r\n")


def is_stream_source(source: str) -> bool:
    """Whether a camera ``source`` names a video stream or file (anything but sim, backend, mcap)."""
    return source not in NON_STREAM_SOURCES


def _port(value: int | None, where: str, source: str) -> int:
    if value is None or not 1 <= value <= 65535:
        raise ValueError(f"{where}: {source!r} needs a UDP/TCP port in [1, 65535]")
    return value


def parse_stream_source(source: str, transport: str | None = None, codec: str | None = None,
                        where: str = "properties.source") -> StreamSpec:
    """Check a camera's stream ``source`` and its stream properties; returns its :class:`StreamSpec`.

    Accepted: ``rtsp://host[:port]/path`` and ``rtsps://`` (``transport`` ``tcp``, the default, or ``udp``);
    ``rtp://[host]:port`` (raw RTP, e.g. ``rtp://0.0.0.0:5600`` for QGC-style senders; ``codec`` ``h264``, the
    default, or ``h265``); ``udp://[host]:port`` (MPEG-TS); ``tcp://host:port`` (MPEG-TS from a TCP server);
    a path ending in ``.sdp`` (the sender's SDP file);
    ``/dev/videoN`` (V4L2); a path or ``file:`` URL ending in a video suffix (:data:`VIDEO_FILE_SUFFIXES`).
    Raises ValueError naming ``where`` (or the property) and the value; file existence is checked by the
    environment loader, which resolves paths."""
    if not isinstance(source, str) or not source.strip() or source != source.strip():
        raise ValueError(f"{where}: a camera source must be a non-empty string without surrounding blanks, got "
                         f"{source!r}")
    if any(ord(c) < 32 for c in source) or len(source) > 2048:
        raise ValueError(f"{where}: {source[:80]!r} has control characters or is longer than 2048 characters")
    if transport is not None and transport not in ("tcp", "udp"):
        raise ValueError(f"properties.transport must be 'tcp' or 'udp', got {transport!r}")
    if codec is not None and codec not in RTP_CODECS:
        raise ValueError(f"properties.codec must be one of {sorted(RTP_CODECS)}, got {codec!r}")
    scheme = source.split("://", 1)[0].lower() if "://" in source else ""
    if scheme not in ("rtsp", "rtsps") and transport is not None:
        raise ValueError(f"properties.transport is only used with an rtsp:// source, but source is {source!r}")
    if scheme != "rtp" and codec is not None:
        raise ValueError(f"properties.codec is only used with an rtp:// source (an RTSP server, an SDP file and "
                         f"MPEG-TS say their codec themselves), but source is {source!r}")
    if scheme in ("rtsp", "rtsps"):
        u = urlsplit(source)
        if not u.hostname:
            raise ValueError(f"{where}: {source!r} names no host (rtsp://host[:port]/path)")
        try:
            u.port
        except ValueError:
            raise ValueError(f"{where}: {source!r} has an invalid port") from None
        return StreamSpec("rtsp", source, source, "rtsp", {"rtsp_transport": transport or "tcp"})
    if scheme == "tcp":
        u = urlsplit(source)
        try:
            port = _port(u.port, where, source)
        except ValueError as e:
            raise ValueError(str(e) if "needs" in str(e) else f"{where}: {source!r} has an invalid port") from None
        if not u.hostname or u.path not in ("", "/") or u.query:
            raise ValueError(f"{where}: {source!r}: a tcp:// source (MPEG-TS from a TCP server) is host:port only")
        return StreamSpec("mpegts_tcp", source, f"tcp://{u.hostname}:{port}", "mpegts", {}, host=u.hostname,
                          port=port)
    if scheme in ("rtp", "udp"):
        u = urlsplit(source)
        try:
            port = _port(u.port, where, source)
        except ValueError as e:
            if "needs" in str(e):
                raise
            raise ValueError(f"{where}: {source!r} has an invalid port") from None
        host = u.hostname or "0.0.0.0"
        if u.path not in ("", "/") or u.query:
            raise ValueError(f"{where}: {source!r}: a {scheme}:// source is host:port only")
        if scheme == "udp":
            url = f"udp://{host}:{port}?overrun_nonfatal=1&fifo_size=1000000&buffer_size=4194304"
            return StreamSpec("mpegts_udp", source, url, "mpegts", {}, host=host, port=port)
        return StreamSpec("rtp", source, None, "sdp", {"protocol_whitelist": "file,udp,rtp"}, host=host, port=port,
                          codec=codec or "h264")
    if scheme == "file":
        source_path = source[len("file://"):]
    elif scheme:
        raise ValueError(f"{where}: unknown camera source {source!r}: one of {list(NON_STREAM_SOURCES)}, an "
                         f"rtsp://, rtsps://, rtp://, udp:// or tcp:// URL, an .sdp file, /dev/videoN or a video file")
    else:
        source_path = source
    if re.fullmatch(r"/dev/video\d+", source_path):
        return StreamSpec("v4l2", source, source_path, "video4linux2", {})
    low = source_path.lower()
    if low.endswith(".sdp"):
        return StreamSpec("sdp", source, source_path, "sdp", {"protocol_whitelist": "file,udp,rtp"})
    if low.endswith(VIDEO_FILE_SUFFIXES):
        return StreamSpec("file", source, source_path, None, {}, live=False)
    raise ValueError(f"{where}: unknown camera source {source!r}: one of {list(NON_STREAM_SOURCES)}, an rtsp://, "
                     f"rtsps://, rtp://, udp:// or tcp:// URL, an .sdp file, /dev/videoN or a video file "
                     f"({', '.join(VIDEO_FILE_SUFFIXES)})")


def with_path(spec: StreamSpec, path: Path) -> StreamSpec:
    """``spec`` (kind file or sdp) reading the resolved file ``path``."""
    return replace(spec, url=str(path))
