"""CameraComponent: a camera sensor inside its drone's actor; its frames come from a frame source
(:mod:`aerodaas.plugins.frames`; the built-ins in :mod:`aerodaas.actors.sensors.frame_sources`: rendered by the simulator,
the vehicle's own stream, a recorded MCAP channel, a video stream: RTSP, RTP/UDP, MPEG-TS/UDP, V4L2, file, or one a
plug-in brings) and are published by reference to every reader in the actor."""
from __future__ import annotations

import dataclasses
import threading
import time
from collections import deque
from typing import Any, Callable

import numpy as np

from aerodaas.backends.base import PoseSample
from aerodaas.protocol.messages import FrameMsg
from aerodaas.model.types import CameraIntrinsics, FrameMeta, FramePose
from aerodaas.plugins.frames import FrameSource, FrameSourceContext, LiveFrameSource, frame_source_class

from aerodaas.actors.data.plane import Cascade, DataPlane
from aerodaas.navigation.gimbal import camera_angles, quaternion_from_euler, wrap_deg
from aerodaas.video.pose import angles_at, pose_sampled_at

#: how long a stream frame captured after the newest clock tick waits for the next one (s): the clock ticks at
#: twice the stream's rate, so this is only reached when the clock stalls
TICK_WAIT_S = 0.25
#: how long a stream frame waits for the vehicle's first position sample after its capture (s), so that its pose is
#: interpolated between samples that enclose the capture: a vehicle's samples arrive one telemetry interval apart
#: (10 Hz by default, ``mavlink.stream_rate_hz``; 0.5 s covers 2 Hz). Past it the newest sample is used (held, not
#: extrapolated) and the frame's ``pose_samples_t`` shows the single sample it came from
POSE_WAIT_S = 0.5


class CameraComponent:
    """A camera sensor. :meth:`capture` (run on the actor's pool when the clock says a frame is due) asks its frame
    source (``src``, a :class:`~aerodaas.plugins.frames.FrameSource` chosen by its sensor class from
    ``properties.source``; ``source`` overrides it) for the frame at the run time and pose — rendered (``sim``), the
    backend's own newest frame (``backend``), a recorded MCAP channel's (``mcap``), a plug-in's — makes it
    read-only, and publishes it. While the previous capture is still being rendered a new one is skipped and
    counted (``dropped_at_camera``). A live source's frame (a video stream: RTSP, RTP/UDP, ...) is captured when it
    arrives, the clock's ticks giving the poses it is tagged with (:meth:`try_capture`). Frames go to the recorder
    by reference.

    A frame is made only when something takes it: a consumer routed from the camera (an analytics, a trajectory
    scheduler's priority port) takes every due frame (``fps``); the recorder (the file and the live view) takes
    those at ``properties.record_fps`` (frames/s of vehicle time, default ``fps``; 0: none), the due frame nearest
    each of its instants, 1 / ``record_fps`` s apart (:meth:`_record_due`). A pulled camera whose only taker is the recorder therefore
    renders at ``record_fps``; its due frames nobody takes are not made, counted in ``frames_not_made`` (never in
    ``dropped_at_camera``). Frames made for a consumer but not at the recorder's rate are counted in
    ``record_skipped``. A camera without a recorder and without a route (built outside a run's plan, read with
    :meth:`get_latest` or :meth:`capture`) makes every due frame."""

    kind = "camera"

    def __init__(self, plane: DataPlane, cid: str, robot_id: str, sensor_id: str, props: dict, world: Any,
                 backend: Any, recorder: Any, epoch_ns: int, source: type[FrameSource] | None = None) -> None:
        self.plane, self.cid = plane, cid
        self.robot_id, self.sensor_id = robot_id, sensor_id
        self.k = CameraIntrinsics.from_hfov(int(props["width"]), int(props["height"]), float(props["hfov_deg"]))
        self.pitch = float(props["pitch_deg"])
        self.source = props.get("source", "sim")
        self.fps = float(props["fps"])
        rate = props.get("record_fps")
        #: frames/s of vehicle time the recorder takes (``properties.record_fps``, at most ``fps``; 0: none)
        self.record_fps = self.fps if rate is None else min(float(rate), self.fps)
        self._every_frame_recorded = self.record_fps >= self.fps
        self._frame_period = 1.0 / self.fps  # the configured one (a stream camera's clock ticks twice as fast)
        #: run time (s) of the recorder's next frame (None: its first frame is the next one made)
        self._next_record_t: float | None = None
        self.world, self.backend = world, backend
        self.recorder = recorder
        self.topic = f"/{robot_id}/camera/{sensor_id}"
        self.epoch_ns = epoch_ns
        if recorder is not None:  # its frame in the transform tree, its calibration beside each image
            recorder.camera(robot_id, sensor_id, self.k.model_dump(), self.pitch)
        self.ticks = 0
        self.frames = 0
        self.dropped_at_camera = 0
        self.shed_late = 0  # of those, frames not rendered because the actor's clock was late (try_capture)
        self.not_recorded = 0  # frames the recorder refused (its queue full)
        self.frames_not_made = 0  # due frames nobody takes: not rendered (see the class docstring)
        self.record_skipped = 0  # frames made for a consumer that the recorder does not take (record_fps)
        #: the last frames' render time and capture dispatch delay (clock tick -> render start on the pool), ms
        self.render_ms: deque[float] = deque(maxlen=4096)
        self.dispatch_ms: deque[float] = deque(maxlen=4096)
        #: CPU seconds of this camera's frame making (its source's ``frame_at``: a simulated camera's render), on
        #: the thread that made each frame (``time.thread_time``): the part of a drone actor's CPU that is the camera's
        self.render_cpu_s = 0.0
        self.latest: tuple | None = None
        self._busy = threading.Lock()
        #: the robot's event sink (DroneComponent.record_event), set by the actor's assembly: video_lost/restored
        self.on_event: Callable[..., None] | None = None
        #: (run time s, position ENU m, yaw deg) of each vehicle position sample a clock tick saw, stamped with the
        #: sample's own time (:meth:`~aerodaas.backends.base.VehicleBackend.pose_sample`), each once, in time order:
        #: the poses a stream frame's is interpolated between
        self._poses: deque[tuple[float, tuple, float]] = deque(maxlen=256)
        #: the gimbal's attitude at each tick (run clock s, GimbalAttitude): a stream frame's is the one at its
        #: capture time (aerodaas.video.pose.angles_at)
        self._gimbals: deque[tuple[float, Any]] = deque(maxlen=256)
        self.stream = None
        self._last_capture_t = float("-inf")  # run-clock capture time of the stream's previous frame
        #: (run time s, time.monotonic() s) of the newest clock tick: maps a stream frame's host times to the run
        #: clock; the condition wakes a capture waiting for the tick after its frame (see _tick_after)
        self._tick_clock: tuple[float, float] | None = None
        self._tick_cond = threading.Condition()
        self._last_gimbal: Any = None  # the gimbal's attitude at the newest tick
        self._halted = False  # the drone's mission is over: frames arriving now are not captured
        self.latency_ms: deque[float] = deque(maxlen=4096)
        self._props = props
        cls = source if source is not None else frame_source_class(self.source)
        #: where the frames come from (aerodaas.plugins.frames): a pulled source is asked at each due tick, a live
        #: one's reader wakes the camera when a frame arrived
        self.src: FrameSource = cls(FrameSourceContext(robot_id, sensor_id, props, self.k, backend, world))
        if isinstance(self.src, LiveFrameSource):
            self.src.start(self._on_stream_frame)
            self.stream = self.src.reader  # None until the vehicle announced it (source "mavlink")
            # a stream frame is captured when it arrives (the reader wakes the camera: _on_stream_frame); the ticks,
            # at twice the stream's nominal rate, sample the pose and gimbal the frames are tagged with and take a
            # frame that arrived while the previous capture was running
            self.fps = 2.0 * self.fps

    @property
    def discovered(self) -> Any:
        """The stream the vehicle announced (a DiscoveredStream), None when the source asked for none."""
        return getattr(self.src, "discovered", None)

    def on_vehicle_connected(self) -> None:
        """After the robot's backend connected: the frame source's :meth:`~aerodaas.plugins.frames.FrameSource.
        on_vehicle_connected` (``source: "mavlink"`` asks the backend for the stream the vehicle announces); a
        stream it found is recorded as a ``video_discovered`` event, also when it then cannot be read. Raises what
        the source raises (StreamDiscoveryError, VideoSourceError)."""
        if self.stream is not None:
            return
        try:
            self.src.on_vehicle_connected()
        finally:
            found = self.discovered
            if found is not None and self.on_event is not None:
                self.on_event("video_discovered", sensor=self.sensor_id, **found.event_fields())
        if isinstance(self.src, LiveFrameSource):
            self.stream = self.src.reader

    def try_capture(self, pose: PoseSample, t: float, tok: Cascade | None, clock_late: bool = False) -> bool:
        """Clock thread: a frame is due at run time ``t`` (s); ``pose`` is the vehicle's newest position sample
        (ENU m, ENU yaw deg) and the run time it is of (at most ``t``). Submits the capture unless the previous one
        is still running, or unless ``clock_late`` (the actor's clock is behind the wall clock: the frame would be
        stale, and rendering it would take CPU from the control ticks the clock is catching up on; counted in
        ``shed_late`` too); either way counted in ``dropped_at_camera``. A stream camera keeps the pose sample and
        the gimbal here and captures only a frame that is waiting (one that arrived while the previous capture ran);
        the others are captured on arrival, late or not (the vehicle's own camera sent them).

        A pulled camera's due frame that nobody takes (no consumer, and not one the recorder takes at
        ``record_fps``: :meth:`_record_due`) is not made: counted in ``frames_not_made``, not in ``ticks``."""
        self._keep_pose(pose)
        position, yaw = pose.position, pose.yaw_deg
        if self.stream is not None:
            self._last_gimbal = self._gimbal(t)
            self._note_tick(t)
            return self.stream.waiting() and self._submit_stream_capture()
        record = self._record_due(t)
        if not record and not self._consumed():
            self.frames_not_made += 1
            return False
        self.ticks += 1
        if clock_late:
            self.dropped_at_camera += 1
            self.shed_late += 1
            return False
        if not self._busy.acquire(blocking=False):
            self.dropped_at_camera += 1
            return False
        if tok is not None:
            tok.add()
        if record:
            self._record_taken(t)
        self.plane.submit(self._capture, position, yaw, t, self.ticks, tok, time.perf_counter(), self._gimbal(t),
                          record)
        return True

    def _consumed(self) -> bool:
        """Whether a consumer takes every frame this camera makes: a route from it that carries its robot's items
        (an analytics, a trajectory scheduler's priority port), or, without a recorder or routes (a camera built
        outside a run's plan), whoever reads it (:meth:`get_latest`)."""
        routes = getattr(self.plane, "routes", None)
        if self.recorder is None or routes is None:
            return True
        return any(len(r) < 4 or r[3] is None or self.robot_id in r[3] for r in routes.get(self.cid, ()))

    def _record_due(self, t: float) -> bool:
        """Whether the recorder takes a frame captured at run time ``t`` (s): every one when ``record_fps`` is
        ``fps``, none without a recorder or with ``record_fps`` 0, else the first frame, then the one nearest each
        instant one record period (1 / ``record_fps`` s) after the previous recorded one's instant (within half a
        frame period of it)."""
        if self.recorder is None or self.record_fps <= 0.0:
            return False
        if self._every_frame_recorded:
            return True
        nxt = self._next_record_t
        return nxt is None or t + 0.5 * self._frame_period >= nxt

    def _record_taken(self, t: float) -> None:
        """The recorder takes the frame at run time ``t`` (s): its next instant is one record period on (from ``t``
        after a jump of the clock of more than a period, so that it does not burst)."""
        if self._every_frame_recorded:
            return
        period, nxt = 1.0 / self.record_fps, self._next_record_t
        self._next_record_t = t + period if nxt is None or t > nxt + period else nxt + period

    def halt(self) -> None:
        """The drone's mission is over (the clock calls no more :meth:`try_capture`): stream frames that arrive from
        now on are not captured, and a capture waiting for a tick stops waiting. Called at every step of a settling
        drone: once halted, it returns at once."""
        if self._halted:
            return
        with self._tick_cond:
            self._halted = True
            self._tick_cond.notify_all()

    def _keep_pose(self, pose: PoseSample) -> None:
        """Keep a position sample for stream frames' poses, once (a tick that saw no new sample adds nothing) and in
        time order (an older one than the newest kept is dropped)."""
        if not self._poses or pose.t > self._poses[-1][0]:
            self._poses.append((float(pose.t), tuple(pose.position), float(pose.yaw_deg)))

    def _note_tick(self, t: float) -> None:
        """A clock tick at run time ``t`` (s), now on the host's monotonic clock."""
        with self._tick_cond:
            self._tick_clock = (t, time.monotonic())
            self._tick_cond.notify_all()

    def _on_stream_frame(self) -> None:
        """The stream reader's thread: a frame arrived. It is captured now (on the actor's pool) unless the clock has
        not ticked yet, the mission is over, or a capture is running (that capture's end takes it)."""
        if self._tick_clock is not None and not self._halted:
            self._submit_stream_capture()

    def _submit_stream_capture(self) -> bool:
        """Submit a stream frame's capture unless one is running; its ``seq`` counts the camera's captures."""
        if not self._busy.acquire(blocking=False):
            return False
        self.ticks += 1
        t, position, yaw = self._poses[-1]
        self.plane.submit(self._capture, position, yaw, t, self.ticks, None, time.perf_counter(), self._last_gimbal)
        return True

    def _tick_after(self, mono: float) -> tuple[float, float]:
        """The newest tick (run time s, monotonic s), once there is one at or after host time ``mono`` (s): a frame
        captured after the newest tick waits for the next one, so that the ticks' poses enclose its capture (at most
        :data:`TICK_WAIT_S`; not when the mission is over)."""
        with self._tick_cond:
            self._tick_cond.wait_for(lambda: self._halted or self._tick_clock[1] >= mono, timeout=TICK_WAIT_S)
            return self._tick_clock

    def _pose_after(self, t: float) -> float:
        """Wait until a position sample at or after run time ``t`` (s, a stream frame's capture) was kept, so that
        the frame's pose is interpolated between samples that enclose it: at most :data:`POSE_WAIT_S`, not when the
        mission is over (the clock's ticks bring the samples: :meth:`try_capture` notifies). Returns how long it
        waited (host seconds)."""
        t0 = time.monotonic()
        with self._tick_cond:
            self._tick_cond.wait_for(lambda: self._halted or (bool(self._poses) and self._poses[-1][0] >= t),
                                     timeout=POSE_WAIT_S)
        return time.monotonic() - t0

    def _gimbal(self, t: float) -> Any:
        """The gimbal's attitude now (the clock thread, at the frame's tick at run time ``t`` s), kept for the
        stream frames captured around it; None: no gimbal."""
        gimbal = self.backend.gimbal if self.backend is not None else None
        g = gimbal.latest() if gimbal is not None else None
        if g is not None and (not self._gimbals or t > self._gimbals[-1][0]):
            self._gimbals.append((t, g))
        return g

    def _gimbal_at(self, t: float, tick: Any) -> Any:
        """The gimbal's attitude at run time ``t`` (a stream frame's capture, s): interpolated between the ticks'
        attitudes around it (:func:`aerodaas.video.pose.angles_at`); ``tick`` (the tick's own) when there are none."""
        if tick is None or not self._gimbals:
            return tick
        samples = list(self._gimbals)
        got = angles_at([(ts, (g.roll_deg, g.pitch_deg, g.yaw_deg)) for ts, g in samples], t)
        if got is None:
            return tick
        (roll, pitch, yaw), _ = got
        near = min(samples, key=lambda s: abs(s[0] - t))[1]  # frame and yaw reference of the nearest report
        return dataclasses.replace(near, roll_deg=roll, pitch_deg=pitch, yaw_deg=yaw,
                                   q=quaternion_from_euler(roll, pitch, yaw))

    def _capture(self, position: tuple, yaw: float, t: float, seq: int, tok: Cascade | None, ticked: float,
                 gimbal: Any = None, record: bool | None = None) -> None:
        dispatch_ms = (time.perf_counter() - ticked) * 1e3
        self.dispatch_ms.append(dispatch_ms)
        try:
            try:
                msg = self._produce(position, yaw, t, seq, dispatch_ms, gimbal, record)
            finally:
                self._busy.release()  # the next frame may be rendered while this one travels downstream
            if self.stream is not None and not self._halted and self.stream.waiting():
                self._submit_stream_capture()  # a frame arrived during this capture: taken now, not at a tick
            if msg is not None:
                self.plane.publish(self.cid, [msg], tok, inline=True)
        finally:
            if tok is not None:
                tok.done()

    def capture(self, position: tuple, yaw: float, t: float, seq: int, tok: Cascade | None = None) -> np.ndarray | None:
        """Produce one frame and hand it to the subscribers in this thread; returns it (None if the source had no
        new frame)."""
        self._keep_pose(PoseSample(t, tuple(position), float(yaw)))
        self._note_tick(t)
        record = self._record_due(t)
        if record:
            self._record_taken(t)
        msg = self._produce(position, yaw, t, seq, 0.0, self._gimbal(t), record)
        if msg is None:
            return None
        self.plane.publish(self.cid, [msg], tok, inline=True)
        return msg.data

    def _produce(self, position: tuple, yaw: float, t: float, seq: int,
                 dispatch_ms: float = 0.0, gimbal: Any = None, record: bool | None = None) -> FrameMsg | None:
        """Render (or fetch) the frame, make it read-only, record it; returns its message. ``dispatch_ms``: how long
        the capture waited for a pool thread after the clock's tick (it joins the frame's trace: the honest tail of
        ``aerodaas bench overhead`` counts it frame by frame); ``gimbal``: the gimbal's attitude at the tick (the
        camera's heading and pitch then come from it) or None (the configured mount ``pitch_deg``); ``record``:
        whether the recorder takes its image (None: decided here at its capture time, a stream frame's)."""
        t0 = time.perf_counter()
        pose = self._frame_pose(position, yaw, gimbal)
        truth: list = []
        timing = None
        if self.stream is not None:
            got = self._from_stream()
            if got is None:
                self.dropped_at_camera += 1
                return None
            frame, pose, timing = got
            t = timing["capture_t"]
            if record is None:
                record = self._record_due(t)
                if record:
                    self._record_taken(t)
            gimbal = self._gimbal_at(t, gimbal)  # the gimbal's attitude at the frame's capture, as its position
            pose = self._frame_pose(pose.position, pose.yaw, gimbal)
        else:  # a pulled source (a live one not opened yet has no frame)
            # made straight in a same-node channel's slot when the source can and the frame travels by one
            out = (self.plane.frame_buffer(self.cid, (self.k.height, self.k.width, 3), self.robot_id)
                   if type(self.src).renders_into and not isinstance(self.src, LiveFrameSource) else None)
            c0 = time.thread_time()
            got = self.src.frame_at(t, pose) if out is None else self.src.frame_at(t, pose, out=out)
            self.render_cpu_s += time.thread_time() - c0  # one capture at a time (``_busy``): no lost update
            out = None
            if got is None:  # no new frame since the last capture
                self.dropped_at_camera += 1
                return None
            frame, t, truth = got.image, got.capture_t, list(got.truth)
        frame.flags.writeable = False  # shared by every reader from here on: nobody may change it
        self.plane.copies.count("materialised")
        wall = time.time()
        self.render_ms.append((time.perf_counter() - t0) * 1e3)
        self.frames += 1
        meta = FrameMeta(robot_id=self.robot_id, sensor_id=self.sensor_id, seq=seq, capture_time=t, wall_time=wall,
                         pose=pose, intrinsics=self.k,
                         arrival_time=timing["arrival_t"] if timing else None,
                         pose_time=timing["pose_t"] if timing else None)
        self.latest = (frame, meta)
        if self.recorder is not None:  # by reference; encoded by the recorder's thread
            t_ns = self.epoch_ns + int(t * 1e9)
            if record is False:  # made for a consumer, not at the recorder's rate (record_fps)
                self.record_skipped += 1
            elif not self.recorder.image(self.topic, t_ns, frame, f"{self.robot_id}/{self.sensor_id}"):
                self.not_recorded += 1  # the recorder's bounded queue was full: counted, never silent
            if truth:
                self.recorder.json("/world/targets", t_ns, {"robot": self.robot_id, "seq": seq, "t": t,
                                                            "targets": truth}, "aerodaas.GroundTruth")
            if gimbal is not None:  # the pose the frame carries, with the gimbal's angles
                self.recorder.json(f"{self.topic}/pose", t_ns, {
                    "robot": self.robot_id, "sensor": self.sensor_id, "seq": seq, "t": t,
                    "position": [float(c) for c in pose.position], "yaw": pose.yaw, "camera_pitch": pose.camera_pitch,
                    "gimbal_pitch_deg": gimbal.pitch_deg, "gimbal_yaw_deg": gimbal.yaw_deg}, "aerodaas.FramePose")
            if timing:  # when the frame was captured and arrived, and the pose it carries
                self.recorder.json(f"{self.topic}/timing", t_ns, {"robot": self.robot_id, "sensor": self.sensor_id,
                                                                 "seq": seq, **timing}, "aerodaas.FrameTiming")
        return FrameMsg(robot=self.robot_id, sim_t=t, data=frame, meta=meta,
                        trace={"capture_wall": wall, "inference_ms": 0.0, "post_ms": 0.0, "dispatch_ms": dispatch_ms})

    def _frame_pose(self, position: tuple, yaw: float, gimbal: Any) -> FramePose:
        """The camera's pose: the vehicle's ``position`` (ENU m), and its heading and pitch from the ``gimbal``'s
        attitude (:func:`aerodaas.navigation.gimbal.camera_angles`; an earth-frame yaw is from north, clockwise)
        or, without one, the vehicle's ``yaw`` (ENU degrees) and the mount's ``pitch_deg``."""
        if gimbal is None:
            return FramePose(position=position, yaw=yaw, camera_pitch=self.pitch)
        if gimbal.yaw_in_earth_frame:
            heading, pitch = wrap_deg(90.0 - gimbal.yaw_deg), -gimbal.pitch_deg
        else:
            heading, pitch = camera_angles(yaw, gimbal.pitch_deg, gimbal.yaw_deg)
        return FramePose(position=position, yaw=heading, camera_pitch=pitch)

    def _from_stream(self) -> tuple[np.ndarray, FramePose, dict] | None:
        """The stream's newest frame not delivered before, its pose at capture and its timing, or None. Its capture
        and arrival times on the run clock are the newest tick's run time plus their host-time offset from that tick
        (the run clock of a stream camera runs at wall rate: speedup 1, checked before Ray), with a tick at or after
        the capture (:meth:`_tick_after`). The timing
        (``aerodaas.FrameTiming``): ``capture_t``, ``arrival_t``, ``pose_t`` (run-clock s), ``age_ms`` (capture to
        hand-off), ``stream_seq``, the vehicle pose at capture (``position`` ENU m, ``yaw`` ENU deg) and
        ``pose_samples_t``: the run times (s) of the two vehicle position samples it was interpolated between (their
        own times, not the ticks' that read them; a capture after the newest sample waits for the next one:
        :meth:`_pose_after`), or of the one used outside them; ``pose_wait_s``: how long (host s) it waited for that
        next sample (:data:`POSE_WAIT_S` when none came: the newest one is held)."""
        for ev in self.stream.drain_events():
            if self.on_event is not None:
                self.on_event(ev.kind, sensor=self.sensor_id, **ev.fields)
        f = self.stream.take()
        if f is None:
            return None
        capture_mono = min(f.capture_mono, time.monotonic())  # an estimate from the PTS is never in the future
        tick_t, tick_mono = self._tick_after(capture_mono)
        now = time.monotonic()
        # never before the previous frame's: a vehicle clock that stalls while the wall clock runs (a real
        # autopilot's time_boot_ms, a starved emulator) would order two frames backwards, and the recorder takes a
        # frame not newer than the last one for a frame sent again (seen under load 37: 7 of 911 frames)
        # (not after the newest tick: one taken after it when the clock stalled or the mission ended has that pose)
        capture_t = max(tick_t - max(0.0, tick_mono - capture_mono), self._last_capture_t + 1e-6)
        arrival_t = max(tick_t - (tick_mono - f.arrival_mono), capture_t)
        self._last_capture_t = capture_t
        waited = self._pose_after(capture_t)
        position, yaw, pose_t, samples_t = pose_sampled_at(list(self._poses), capture_t)
        pose = FramePose(position=position, yaw=yaw, camera_pitch=self.pitch)
        self.latency_ms.append((now - f.capture_mono) * 1e3)
        # the pose itself and the ticks it came from, so that the recording can show it is the capture's
        return f.image, pose, {"capture_t": capture_t, "arrival_t": arrival_t, "pose_t": pose_t,
                               "stream_seq": f.seq, "age_ms": round((now - f.capture_mono) * 1e3, 2),
                               "position": [float(c) for c in position], "yaw": float(yaw),
                               "pose_samples_t": list(samples_t), "pose_wait_s": round(waited, 4)}

    def close(self) -> None:
        """Close the frame source; a video stream's reader (if any) records its final counters on
        ``<topic>/video_stats`` (``aerodaas.VideoStats``: decoded = taken + overwritten + waiting; taken -
        not_recorded frames are in the recording)."""
        try:
            self.src.close()
        except Exception as e:  # noqa: BLE001 - reported; the stream's counters must still be recorded
            self.plane.report_error(f"{self.robot_id}/{self.sensor_id} frame source close", e)
        if self.stream is None:
            return
        self.stream.close()
        if self.recorder is not None:
            t = self._poses[-1][0] if self._poses else 0.0
            self.recorder.json(f"{self.topic}/video_stats", self.epoch_ns + int(t * 1e9),
                               {"robot": self.robot_id, "sensor": self.sensor_id, **self._video_stats()},
                               "aerodaas.VideoStats")

    def get_latest(self) -> tuple | None:
        """(frame, FrameMeta) of the newest frame, for pull-style access."""
        return self.latest

    def stats(self) -> dict:
        r = np.array(self.render_ms or [0.0])
        q = np.array(self.dispatch_ms or [0.0])
        return {"frames": self.frames, "ticks": self.ticks, "dropped_at_camera": self.dropped_at_camera,
                "shed_late": self.shed_late, "frames_not_made": self.frames_not_made,
                "record_fps": self.record_fps, "record_skipped": self.record_skipped,
                "render_ms_median": float(np.median(r)), "render_cpu_s": round(self.render_cpu_s, 6),
                "dispatch_ms_median": float(np.median(q)), "dispatch_ms_p99": float(np.percentile(q, 99)),
                "recorder_dropped": getattr(self.recorder, "frames_dropped", 0) if self.recorder else 0,
                "outlets": self.plane.outlet_stats(self.cid), "subscribers": len(self.plane.routes.get(self.cid, [])),
                **({"video": self._video_stats()} if self.stream is not None else {})}

    def _video_stats(self) -> dict:
        """The stream's counters (:meth:`aerodaas.video.StreamReader.stats`) and its capture-to-delivery latency
        (ms: median, p99, max) — the glass-to-analytics time up to the camera's hand-off."""
        lat = np.array(self.latency_ms or [0.0])
        found = {"discovered": self.discovered.describe()} if self.discovered is not None else {}
        return {**self.stream.stats(), **found, "not_recorded": self.not_recorded, "latency_ms_median": float(np.median(lat)),
                "latency_ms_p99": float(np.percentile(lat, 99)), "latency_ms_max": float(lat.max())}
