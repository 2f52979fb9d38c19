"""The run's MCAP writer, living in the edge host process (no extra Ray worker, no copy of the frames).

Every component hands it messages with non-blocking calls; a writer thread JPEG-encodes frames and writes
everything through :class:`aerodaas.recording.McapRecorder` (zstd chunks, flushed as chunks complete and at
least every ``flush_every_s`` seconds, so a crash loses at most the last couple of seconds).

A failing disk (full, I/O error, gone) stops the recording cleanly instead of killing the writer thread: the file
is cut back to the last record boundary the OS accepted and finished if the disk still takes the summary (else it
stays unfinished, readable by ``aerodaas info`` and made whole by ``aerodaas recover``); the failure is reported
to ``on_failure`` callbacks (the drones record it as a ``recording_failed`` event) and in :meth:`report`, and every
message offered afterwards is counted as lost. ``AERODAAS_FAULT_RECORDER=enospc:N`` (or ``eio:N``) injects that
failure once N bytes have been written (the fault suite of :mod:`aerodaas.reliability`).
"""
from __future__ import annotations

import errno
import os
import queue
import threading
import time
from typing import Any, Callable

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
        self.failure: dict[str, Any] | None = None
        self.lost = 0  # messages offered after a failure (not recorded)
        self.last_t_ns: int | None = None  # log time of the last message written
        self.on_failure: list[Callable[[dict], None]] = []
        _inject_fault(self.rec)
        self._thread = threading.Thread(target=self._writer, name="aerodaas-recorder", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ producers
    def image(self, topic: str, t_ns: int, frame: np.ndarray, frame_id: str) -> bool:
        """Queue a (H, W, 3) uint8 BGR frame (shared, not copied: frames are read-only). False if dropped."""
        with self._lock:
            if self.failure is not None:
                self.lost += 1
                return False
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
        if self.failure is not None:
            self.lost += 1
        elif not self.closed:
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
            try:
                if item is not None:
                    try:
                        self._write(item)
                        self.last_t_ns = item[2]
                    except OSError:
                        raise
                    except Exception as e:  # a bad message must not stop the recording
                        self.write_errors.append(f"{item[0]} {item[1]}: {type(e).__name__}: {e}")
                    finally:
                        if item[0] == "image":
                            with self._lock:
                                self._pending_frames -= 1
                if time.monotonic() - last_flush > self.flush_every_s:
                    self.rec.flush()
                    last_flush = time.monotonic()
            except OSError as e:  # the disk: full, I/O error, gone. Stop cleanly, say what was lost.
                self._fail(e)
                return

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

    def _fail(self, e: OSError) -> None:
        """The writer hit ``e``: cut the file back to the last record boundary the OS took, try to finish it, count
        what is lost, tell the callbacks. Runs in the writer thread, which then ends."""
        rec = self.rec
        info: dict[str, Any] = {"error": f"{type(e).__name__}: {e}", "errno": e.errno,
                                "last_recorded_ns": self.last_t_ns, "path": self.path}
        with self._lock:
            self.failure = info
        lost = 0
        while True:  # what was queued is lost too
            try:
                item = self._q.get_nowait()
            except queue.Empty:
                break
            if item[0] != "stop":
                lost += 1
        self.lost += lost
        durable = rec._stream.durable
        try:
            rec._file.close()  # its pending buffer cannot be written: close the descriptor anyway
        except OSError:
            pass
        rec._closed = True
        finished = False
        try:
            os.truncate(rec.path, durable)  # the file ends at a complete record: an unfinished but valid MCAP
            from aerodaas.recover import recover_mcap

            info["messages_in_file"] = recover_mcap(rec.path)["messages"]  # finished and indexed, if the disk
            finished = True  # still takes it
        except OSError as e2:
            info["finish_error"] = f"{type(e2).__name__}: {e2}"
        info["finished"] = finished
        for cb in list(self.on_failure):
            try:
                cb(dict(info))
            except Exception:  # noqa: BLE001 - a reporting callback must not hide the failure
                pass

    # ------------------------------------------------------------------ end
    def close(self, timeout_s: float = 30.0) -> dict[str, Any]:
        """Write what is queued, finish the file (summary and footer) and return the per-topic message counts."""
        if not self.closed:
            self.closed = True
            self._q.put(("stop",))
            self._thread.join(timeout_s)
            if self.failure is None:
                try:
                    self.rec.close()
                except OSError as e:  # the summary itself does not fit: the same clean failure
                    self._fail(e)
        return dict(self.rec.message_counts)

    def report(self) -> dict[str, Any]:
        """``{"failure": None | {error, errno, last_recorded_ns, path, finished, finish_error?}, "lost": n,
        "frames_dropped": n, "write_errors": [...]}``."""
        return {"failure": self.failure, "lost": self.lost, "frames_dropped": self.frames_dropped,
                "write_errors": self.write_errors[-10:]}

    def counts(self) -> dict[str, int]:
        return dict(self.rec.message_counts)


def _inject_fault(rec: McapRecorder) -> None:
    """``AERODAAS_FAULT_RECORDER=enospc:N`` / ``eio:N``: the recording's file fails with ENOSPC / EIO once N bytes
    were written (fault injection; unset in normal runs)."""
    spec = os.environ.get("AERODAAS_FAULT_RECORDER")
    if not spec:
        return
    kind, _, n = spec.partition(":")
    code = {"enospc": errno.ENOSPC, "eio": errno.EIO}[kind.strip().lower()]
    limit = int(n)
    f = rec._file
    real_write = f.write

    def write(data: bytes) -> int:
        if f.tell() + len(data) > limit:
            raise OSError(code, os.strerror(code))
        return real_write(data)

    rec._stream._f = type("_Faulty", (), {"write": staticmethod(write), "flush": f.flush, "tell": f.tell,
                                          "fileno": f.fileno, "close": f.close})()
