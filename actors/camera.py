"""CameraComponent: a camera sensor inside its drone's actor (rendered by the simulator, the vehicle's own stream,
or a recorded MCAP channel); frames are published by reference to every reader in the actor."""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

import numpy as np

from aerodaas.runtime.messages import FrameMsg
from aerodaas.app.models import CameraIntrinsics, FrameMeta, FramePose

from aerodaas.actors.dataplane import Cascade, DataPlane


class CameraComponent:
    """A camera sensor. :meth:`capture` (run on the actor's pool when the clock says a frame is due) produces one
    frame — rendered by the simulator at the drone's pose (``source: sim``), the backend's own newest frame
    (``source: backend``, e.g. a Tello), or the recorded frame at this time of an MCAP recording's camera channel
    (``source: mcap``, to re-run analytics on a recorded flight) — makes it read-only, and publishes it. While the previous capture is still being
    rendered a new one is skipped and counted (``dropped_at_camera``). Frames go to the recorder by reference."""

    kind = "camera"

    def __init__(self, plane: DataPlane, cid: str, robot_id: str, sensor_id: str, props: dict, world: Any,
                 backend: Any, recorder: Any, epoch_ns: int) -> None:
        self.plane, self.cid = plane, cid
        self.robot_id, self.sensor_id = robot_id, sensor_id
        self.k = CameraIntrinsics.from_hfov(int(props["width"]), int(props["height"]), float(props["hfov_deg"]))
        self.pitch = float(props["pitch_deg"])
        self.source = props.get("source", "sim")
        self.fps = float(props["fps"])
        self.world, self.backend = world, backend
        self.recorder = recorder
        self.topic = f"/{robot_id}/camera/{sensor_id}"
        self.epoch_ns = epoch_ns
        if recorder is not None:  # its frame in the transform tree, its calibration beside each image
            recorder.camera(robot_id, sensor_id, self.k.model_dump(), self.pitch)
        self.ticks = 0
        self.frames = 0
        self.dropped_at_camera = 0
        #: the last frames' render time and capture dispatch delay (clock tick -> render start on the pool), ms
        self.render_ms: deque[float] = deque(maxlen=4096)
        self.dispatch_ms: deque[float] = deque(maxlen=4096)
        self.latest: tuple | None = None
        self._busy = threading.Lock()
        self._last_source_t: float | None = None
        self.replay = None
        if self.source == "mcap":
            from aerodaas.backends.replay import McapCameraReplay

            self.replay = McapCameraReplay(props["mcap"], props.get("topic") or f"/{robot_id}/camera/{sensor_id}")

    def try_capture(self, position: tuple, yaw: float, t: float, tok: Cascade | None) -> bool:
        """Clock thread: a frame is due. Submits the capture unless the previous one is still running."""
        self.ticks += 1
        if not self._busy.acquire(blocking=False):
            self.dropped_at_camera += 1
            return False
        if tok is not None:
            tok.add()
        self.plane.submit(self._capture, position, yaw, t, self.ticks, tok, time.perf_counter())
        return True

    def _capture(self, position: tuple, yaw: float, t: float, seq: int, tok: Cascade | None, ticked: float) -> None:
        dispatch_ms = (time.perf_counter() - ticked) * 1e3
        self.dispatch_ms.append(dispatch_ms)
        try:
            try:
                msg = self._produce(position, yaw, t, seq, dispatch_ms)
            finally:
                self._busy.release()  # the next frame may be rendered while this one travels downstream
            if msg is not None:
                self.plane.publish(self.cid, [msg], tok, inline=True)
        finally:
            if tok is not None:
                tok.done()

    def capture(self, position: tuple, yaw: float, t: float, seq: int, tok: Cascade | None = None) -> np.ndarray | None:
        """Produce one frame and hand it to the subscribers in this thread; returns it (None if the source had no
        new frame)."""
        msg = self._produce(position, yaw, t, seq)
        if msg is None:
            return None
        self.plane.publish(self.cid, [msg], tok, inline=True)
        return msg.data

    def _produce(self, position: tuple, yaw: float, t: float, seq: int,
                 dispatch_ms: float = 0.0) -> FrameMsg | None:
        """Render (or fetch) the frame, make it read-only, record it; returns its message. ``dispatch_ms``: how long
        the capture waited for a pool thread after the clock's tick (it joins the frame's trace: the honest tail of
        ``aerodaas bench overhead`` counts it frame by frame)."""
        t0 = time.perf_counter()
        pose = FramePose(position=position, yaw=yaw, camera_pitch=self.pitch)
        truth: list = []
        if self.source in ("backend", "mcap"):
            got = self.backend.camera_frame() if self.replay is None else self.replay.frame_at(t)
            if got is None or got[1] == self._last_source_t:  # no new frame since the last capture
                self.dropped_at_camera += 1
                return None
            frame, t = got
            self._last_source_t = t
        else:
            frame, truth = self.world.render(pose, self.k, t)
        frame.flags.writeable = False  # shared by every reader from here on: nobody may change it
        self.plane.copies.count("materialised")
        wall = time.time()
        self.render_ms.append((time.perf_counter() - t0) * 1e3)
        self.frames += 1
        meta = FrameMeta(robot_id=self.robot_id, sensor_id=self.sensor_id, seq=seq, capture_time=t, wall_time=wall,
                         pose=pose, intrinsics=self.k)
        self.latest = (frame, meta)
        if self.recorder is not None:  # by reference; encoded by the recorder's thread
            t_ns = self.epoch_ns + int(t * 1e9)
            self.recorder.image(self.topic, t_ns, frame, f"{self.robot_id}/{self.sensor_id}")
            if truth:
                self.recorder.json("/world/targets", t_ns, {"robot": self.robot_id, "seq": seq, "t": t,
                                                            "targets": truth}, "aerodaas.GroundTruth")
        return FrameMsg(robot=self.robot_id, sim_t=t, data=frame, meta=meta,
                        trace={"capture_wall": wall, "inference_ms": 0.0, "post_ms": 0.0, "dispatch_ms": dispatch_ms})

    def get_latest(self) -> tuple | None:
        """(frame, FrameMeta) of the newest frame, for pull-style access."""
        return self.latest

    def stats(self) -> dict:
        r = np.array(self.render_ms or [0.0])
        q = np.array(self.dispatch_ms or [0.0])
        return {"frames": self.frames, "ticks": self.ticks, "dropped_at_camera": self.dropped_at_camera,
                "render_ms_median": float(np.median(r)),
                "dispatch_ms_median": float(np.median(q)), "dispatch_ms_p99": float(np.percentile(q, 99)),
                "recorder_dropped": getattr(self.recorder, "frames_dropped", 0) if self.recorder else 0,
                "outlets": self.plane.outlet_stats(self.cid), "subscribers": len(self.plane.routes.get(self.cid, []))}
