"""A video stream read into a newest-wins slot by a thread of its own: decoding never waits for the consumer and
latency never grows.

:class:`StreamReader` opens a :class:`~aerodaas.video.source.StreamSpec` with PyAV (FFmpeg), decodes every frame
into ``(height, width, 3) uint8 BGR`` (scaled by FFmpeg's swscale when the stream's size differs from the
camera's), stamps it (:class:`~aerodaas.video.clock.CaptureClock`) and puts it into a one-frame slot; a frame
replaced before anybody took it is counted (``overwritten``). A live stream that stops (no packet within
``stall_timeout_s``, an error, or its end) is reopened with exponential backoff, and ``video_lost`` /
``video_restored`` events are queued for the camera to record. A file is paced at its own frame rate and looped.

Counts (:meth:`StreamReader.stats`): ``decoded`` = ``taken`` + ``overwritten`` + (1 if a frame waits in the slot).
"""
from __future__ import annotations

import os
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Literal

import numpy as np

from aerodaas.video.clock import CaptureClock
from aerodaas.video.source import StreamSpec


class VideoSourceError(RuntimeError):
    """A video source that gave no frame in time (the message names the URL), or one that cannot be opened."""


@dataclass(frozen=True)
class VideoFrame:
    """One decoded frame. ``seq``: 1, 2, ... in decode order over the whole run (across reopens); ``image``:
    ``(H, W, 3) uint8 BGR``, read-only; ``capture_mono`` / ``arrival_mono``: this host's ``time.monotonic`` (s) of
    its capture (estimated from its PTS) and of its decode; ``pts_s``: its presentation time (s, sender clock)."""

    seq: int
    image: np.ndarray
    capture_mono: float
    arrival_mono: float
    pts_s: float | None


@dataclass(frozen=True)
class VideoEvent:
    """``video_lost`` (the stream stopped; fields: url, reason, last_frame_s_ago) or ``video_restored`` (frames
    again; fields: url, outage_s, reopen_attempts), at ``mono`` (this host's monotonic s)."""

    kind: Literal["video_lost", "video_restored"]
    mono: float
    fields: dict[str, Any] = field(default_factory=dict)


class StreamReader:
    """Reads ``spec`` in a daemon thread (see the module docstring). ``width``/``height``: the camera's frame size
    in px; ``stall_timeout_s``: no packet for this long means the stream is lost; ``open_timeout_s``: how long one
    open may take; ``backoff_s``: (first, longest) wait between reopen attempts; ``on_frame``: called (no
    arguments, in the reading thread) each time a frame was put into the slot — the consumer's wake-up, so that it
    takes a frame when it arrives instead of polling; it must not block (an exception from it is counted in
    ``on_frame_errors`` and the reading goes on). Call :meth:`start`, then :meth:`wait_first`, :meth:`take`,
    :meth:`drain_events`; :meth:`close` at the end."""

    def __init__(self, spec: StreamSpec, width: int, height: int, *, stall_timeout_s: float = 2.0,
                 open_timeout_s: float = 10.0, backoff_s: tuple[float, float] = (0.25, 4.0), name: str = "",
                 on_frame: Callable[[], None] | None = None) -> None:
        self.spec, self.width, self.height = spec, int(width), int(height)
        self.on_frame = on_frame
        self.on_frame_errors = 0
        self.stall_timeout_s, self.open_timeout_s, self.backoff_s = stall_timeout_s, open_timeout_s, backoff_s
        self.name = name or spec.source
        self.clock = CaptureClock()
        self._lock = threading.Lock()
        self._slot: VideoFrame | None = None
        self._events: list[VideoEvent] = []
        self._stop = threading.Event()
        self._first = threading.Event()
        self._thread: threading.Thread | None = None
        self._sdp_path: str | None = None
        self.decoded = self.taken = self.overwritten = 0
        self.opens = self.open_failures = self.decode_errors = 0
        self.lost = self.restored = 0
        self.outage_s = 0.0
        self.last_error: str | None = None
        self._lost_at: float | None = None
        self._last_arrival: float | None = None
        self._attempts_since_loss = 0

    # ------------------------------------------------------------------ consumer side
    def start(self) -> "StreamReader":
        """Start the reading thread (writes the SDP file first for a raw RTP source)."""
        if self.spec.kind == "rtp":
            fd, self._sdp_path = tempfile.mkstemp(prefix="aerodaas-", suffix=".sdp")
            with os.fdopen(fd, "w") as f:
                f.write(self.spec.sdp_text())
        self._thread = threading.Thread(target=self._run, name=f"video:{self.name}", daemon=True)
        self._thread.start()
        return self

    def wait_first(self, timeout_s: float) -> None:
        """Block until the first frame is decoded. Raises :class:`VideoSourceError` naming the URL (and the last
        FFmpeg error) when none came within ``timeout_s`` seconds."""
        if not self._first.wait(timeout_s):
            self.close()
            why = f" (last error: {self.last_error})" if self.last_error else ""
            raise VideoSourceError(f"no video frame from {self.spec.source!r} within {timeout_s:g} s"
                                   f" ({self.opens} open(s), {self.open_failures} failed){why}")

    def take(self) -> VideoFrame | None:
        """The newest frame not taken before (None: none new since the last call): a frame is delivered once."""
        with self._lock:
            f, self._slot = self._slot, None
            if f is not None:
                self.taken += 1
            return f

    def waiting(self) -> bool:
        """Whether a frame waits in the slot (one :meth:`take` would return)."""
        with self._lock:
            return self._slot is not None

    def drain_events(self) -> list[VideoEvent]:
        """The events since the last call, oldest first."""
        with self._lock:
            ev, self._events = self._events, []
            return ev

    def stats(self) -> dict[str, Any]:
        """Counters: decoded, taken, overwritten (newest-wins drops), waiting (0/1), opens, open_failures,
        decode_errors, lost, restored, outage_s (total seconds without frames after a loss), clock_resets,
        on_frame_errors."""
        with self._lock:
            waiting = int(self._slot is not None)
            outage = self.outage_s + (time.monotonic() - self._lost_at if self._lost_at is not None else 0.0)
            return {"source": self.spec.source, "kind": self.spec.kind, "decoded": self.decoded, "taken": self.taken,
                    "overwritten": self.overwritten, "waiting": waiting, "opens": self.opens,
                    "open_failures": self.open_failures, "decode_errors": self.decode_errors, "lost": self.lost,
                    "restored": self.restored, "outage_s": round(outage, 3), "clock_resets": self.clock.resets,
                    "on_frame_errors": self.on_frame_errors}

    def close(self) -> None:
        """Stop the thread (within about one read timeout) and remove the SDP file."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=self.stall_timeout_s + self.open_timeout_s + 1.0)
        if self._sdp_path:
            try:
                os.unlink(self._sdp_path)
            except OSError:
                pass
            self._sdp_path = None

    # ------------------------------------------------------------------ reading thread
    def _run(self) -> None:
        import av  # lazy: heavy av

        backoff = self.backoff_s[0]
        while not self._stop.is_set():
            url = self._sdp_path if self.spec.kind == "rtp" else self.spec.url
            try:
                opts = dict(self.spec.options)
                if self.spec.live:
                    opts.setdefault("fflags", "nobuffer")
                container = av.open(url, format=self.spec.format, options=opts,
                                    timeout=(self.open_timeout_s, self.stall_timeout_s))
            except Exception as e:  # noqa: BLE001 - every FFmpeg/OS failure to open is a retry
                self.open_failures += 1
                self.last_error = f"{type(e).__name__}: {e}"
                self._note_loss("cannot open: " + self.last_error)
                self._stop.wait(backoff)
                backoff = min(backoff * 2.0, self.backoff_s[1])
                continue
            self.opens += 1
            self.clock.reset()
            try:
                got = self._read(container)
            finally:
                try:
                    container.close()
                except Exception:  # noqa: BLE001
                    pass
            if got:
                backoff = self.backoff_s[0]
            if self._stop.is_set():
                break
            if self.spec.live:
                self._note_loss(self.last_error or "end of stream")
                self._stop.wait(backoff)
                backoff = min(backoff * 2.0, self.backoff_s[1])

    def _read(self, container) -> int:
        """Decode ``container`` until it ends, fails or the reader stops; returns the number of frames decoded."""
        import av  # lazy: heavy av

        n = 0
        stream = container.streams.video[0]
        stream.thread_type = "SLICE"  # frame threading holds frames back: latency; slices do not
        pace_anchor: tuple[float, float] | None = None
        try:
            for packet in container.demux(stream):
                if self._stop.is_set():
                    break
                try:
                    frames = packet.decode()
                except av.error.FFmpegError as e:
                    self.decode_errors += 1  # a damaged packet (lost UDP datagram): the next keyframe heals it
                    self.last_error = f"decode: {e}"
                    continue
                for frame in frames:
                    pts = float(frame.time) if frame.time is not None else None
                    if not self.spec.live:  # a file plays at its own rate, like a camera
                        now = time.monotonic()
                        if pts is None or pace_anchor is None or pts < pace_anchor[1]:
                            pace_anchor = (now, pts or 0.0)
                        due = pace_anchor[0] + ((pts or 0.0) - pace_anchor[1])
                        if due - now > 0:
                            if self._stop.wait(min(due - now, 1.0)):
                                return n
                        elif now - due > 0.5:  # far behind (a loaded host): start pacing again from now
                            pace_anchor = (now, pts or 0.0)
                    img = frame.reformat(width=self.width, height=self.height, format="bgr24").to_ndarray()
                    img.flags.writeable = False
                    arrival = time.monotonic()
                    capture = arrival if not self.spec.live else self.clock.capture(pts, arrival)
                    self._put(img, capture, arrival, pts)
                    n += 1
        except Exception as e:  # noqa: BLE001 - a read timeout (stall), a reset connection: the stream stopped
            self.last_error = f"{type(e).__name__}: {e}"
            return n
        self.last_error = None if n else self.last_error
        return n

    def _put(self, img: np.ndarray, capture: float, arrival: float, pts: float | None) -> None:
        with self._lock:
            self.decoded += 1
            if self._slot is not None:
                self.overwritten += 1
            self._slot = VideoFrame(self.decoded, img, capture, arrival, pts)
            if self._lost_at is not None:
                outage = arrival - self._lost_at
                self.outage_s += outage
                self.restored += 1
                self._events.append(VideoEvent("video_restored", arrival, {
                    "url": self.spec.source, "outage_s": round(outage, 3),
                    "reopen_attempts": self._attempts_since_loss}))
                self._lost_at = None
            self._last_arrival = arrival
            self._attempts_since_loss = 0
        self._first.set()
        if self.on_frame is not None:
            try:
                self.on_frame()
            except Exception:  # noqa: BLE001 - the consumer's wake-up failing must not stop the stream
                self.on_frame_errors += 1

    def _note_loss(self, reason: str) -> None:
        """The stream stopped (or still cannot be opened): one ``video_lost`` per outage, after a first frame."""
        with self._lock:
            self._attempts_since_loss += 1
            if self._lost_at is not None or self._last_arrival is None:
                return
            now = time.monotonic()
            self._lost_at = self._last_arrival
            self.lost += 1
            self._events.append(VideoEvent("video_lost", now, {
                "url": self.spec.source, "reason": reason[:300],
                "last_frame_s_ago": round(now - self._last_arrival, 3)}))
