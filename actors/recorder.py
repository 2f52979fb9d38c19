"""RecorderActor: the single writer of a run's MCAP file; every other actor sends it one-way calls."""
from __future__ import annotations

import time
from typing import Any

import ray

from aerodaas.recording import McapRecorder


@ray.remote(num_cpus=0, max_concurrency=1)
class RecorderActor:
    """Wraps :class:`aerodaas.recording.McapRecorder`. Frames arrive as ``[ObjectRef]`` (zero-copy on the node)."""

    def __init__(self, path: str, metadata: dict[str, str] | None = None, jpeg_quality: int = 80) -> None:
        self.rec = McapRecorder(path, metadata=metadata, jpeg_quality=jpeg_quality)
        self.closed = False
        self._last_flush = time.monotonic()

    def _maybe_flush(self) -> None:
        # bound what a crash can lose for slow streams: close the open chunk at least every 2 s
        if time.monotonic() - self._last_flush > 2.0:
            self.rec.flush()
            self._last_flush = time.monotonic()

    def image(self, topic: str, t_ns: int, frame_ref: list, frame_id: str) -> None:
        if not self.closed:
            self.rec.write_image(topic, t_ns, ray.get(frame_ref[0]), frame_id=frame_id)

    def detections(self, topic: str, t_ns: int, dets: list, image_size: tuple[int, int] | None = None) -> None:
        if not self.closed:
            self.rec.write_detections(topic, t_ns, dets, image_size=image_size)

    def odometry(self, robot: str, t_ns: int, odom: dict) -> None:
        if self.closed:
            return
        g = odom["geodetic"]
        self.rec.write_location(f"/{robot}/gps", t_ns, g["lat"], g["lon"], g["alt"], frame_id=f"{robot}/gps")
        att = odom["attitude"]
        self.rec.write_pose(f"/{robot}/pose", t_ns, odom["position"], att["yaw"], frame_id="enu",
                            roll_deg=att["roll"], pitch_deg=att["pitch"])
        self.rec.write_transform("/tf", t_ns, "enu", f"{robot}/base_link", odom["position"], att["yaw"],
                                 roll_deg=att["roll"], pitch_deg=att["pitch"])
        self.rec.write_json(f"/{robot}/odometry", t_ns, odom, schema_name="aerodaas.Odometry")
        self._maybe_flush()

    def json(self, topic: str, t_ns: int, obj: dict, schema_name: str) -> None:
        if not self.closed:
            self.rec.write_json(topic, t_ns, obj, schema_name=schema_name)
            self._maybe_flush()

    def counts(self) -> dict[str, int]:
        return dict(self.rec.message_counts)

    def close(self) -> dict[str, Any]:
        if not self.closed:
            self.closed = True
            self.rec.close()
        return dict(self.rec.message_counts)
