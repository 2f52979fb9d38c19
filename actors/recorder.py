"""The run's MCAP writer, living in the edge host process (no extra Ray worker, no copy of the frames).

Every component hands it messages with non-blocking calls; a writer thread JPEG-encodes frames and writes
everything through :class:`aerodaas.recording.McapRecorder` (zstd chunks, flushed as chunks complete and at
least every ``flush_every_s`` seconds, so a crash loses at most the last couple of seconds).
"""
from __future__ import annotations

import queue
import threading
import time
from typing import Any

import numpy as np

from aerodaas.recording import McapRecorder


class RecorderService:
    """Asynchronous recorder. ``max_pending_frames`` bounds the frames waiting to be encoded: beyond it new frames
    are dropped and counted (``frames_dropped``) instead of growing memory or slowing the camera; JSON and
    telemetry messages are never dropped. Each frame written is JPEG-encoded exactly once, counted as
    ``recorder_jpeg_encoded`` in ``copies`` (the host's :class:`~.host.FrameCopies`) when given. All methods are
    thread-safe and return at once."""

    def __init__(self, path: str, metadata: dict[str, str] | None = None, jpeg_quality: int = 80,
                 max_pending_frames: int = 8, flush_every_s: float = 2.0, copies: Any = None) -> None:
        self.rec = McapRecorder(path, metadata=metadata, jpeg_quality=jpeg_quality)
        self.path = path
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._pending_frames = 0
        self._lock = threading.Lock()
        self.max_pending_frames = max_pending_frames
        self.flush_every_s = flush_every_s
        self.copies = copies
        self.frames_dropped = 0
        self.write_errors: list[str] = []
        self.closed = False
        self._thread = threading.Thread(target=self._writer, name="aerodaas-recorder", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ producers
    def image(self, topic: str, t_ns: int, frame: np.ndarray, frame_id: str) -> bool:
        """Queue a (H, W, 3) uint8 BGR frame (shared, not copied: frames are read-only). False if dropped."""
        with self._lock:
            if self.closed or self._pending_frames >= self.max_pending_frames:
                self.frames_dropped += 1
                return False
            self._pending_frames += 1
        self._q.put(("image", topic, t_ns, frame, frame_id))
        return True

    def detections(self, topic: str, t_ns: int, dets: list, image_size: tuple[int, int] | None = None) -> None:
        self._put(("detections", topic, t_ns, dets, image_size))

    def odometry(self, robot: str, t_ns: int, odom: dict) -> None:
        self._put(("odometry", robot, t_ns, odom))

    def json(self, topic: str, t_ns: int, obj: dict, schema_name: str) -> None:
        self._put(("json", topic, t_ns, obj, schema_name))

    def _put(self, item: tuple) -> None:
        if not self.closed:
            self._q.put(item)

    # ------------------------------------------------------------------ writer thread
    def _writer(self) -> None:
        last_flush = time.monotonic()
        while True:
            try:
                item = self._q.get(timeout=0.5)
            except queue.Empty:
                item = None
            if item is not None and item[0] == "stop":
                return
            if item is not None:
                try:
                    self._write(item)
                except Exception as e:  # a bad message must not stop the recording
                    self.write_errors.append(f"{item[0]} {item[1]}: {type(e).__name__}: {e}")
                finally:
                    if item[0] == "image":
                        with self._lock:
                            self._pending_frames -= 1
            if time.monotonic() - last_flush > self.flush_every_s:
                self.rec.flush()
                last_flush = time.monotonic()

    def _write(self, item: tuple) -> None:
        kind = item[0]
        r = self.rec
        if kind == "image":
            _, topic, t_ns, frame, frame_id = item
            r.write_image(topic, t_ns, frame, frame_id=frame_id)  # the one JPEG encode of this frame
            if self.copies is not None:
                self.copies.count("recorder_jpeg_encoded")
        elif kind == "detections":
            _, topic, t_ns, dets, size = item
            r.write_detections(topic, t_ns, dets, image_size=size)
        elif kind == "json":
            _, topic, t_ns, obj, schema = item
            r.write_json(topic, t_ns, obj, schema_name=schema)
        elif kind == "odometry":
            _, robot, t_ns, odom = item
            g = odom["geodetic"]
            r.write_location(f"/{robot}/gps", t_ns, g["lat"], g["lon"], g["alt"], frame_id=f"{robot}/gps")
            att = odom["attitude"]
            r.write_pose(f"/{robot}/pose", t_ns, odom["position"], att["yaw"], frame_id="enu",
                         roll_deg=att["roll"], pitch_deg=att["pitch"])
            r.write_transform("/tf", t_ns, "enu", f"{robot}/base_link", odom["position"], att["yaw"],
                              roll_deg=att["roll"], pitch_deg=att["pitch"])
            r.write_json(f"/{robot}/odometry", t_ns, odom, schema_name="aerodaas.Odometry")

    # ------------------------------------------------------------------ end
    def close(self, timeout_s: float = 30.0) -> dict[str, Any]:
        """Write what is queued, finish the file (summary and footer) and return the per-topic message counts."""
        if not self.closed:
            self.closed = True
            self._q.put(("stop",))
            self._thread.join(timeout_s)
            self.rec.close()
        return dict(self.rec.message_counts)

    def counts(self) -> dict[str, int]:
        return dict(self.rec.message_counts)
