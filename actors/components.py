"""The components a host runs — cameras, analytics, trajectory schedulers, drones — and :class:`HostRuntime`,
which builds them from the driver's spec, runs the clock and answers the driver's calls.

Envelopes between components are dicts ``{"kind", "data", "meta", "sim_t", "trace", "robot"}``: ``kind`` is
``frame`` (data: a read-only (H, W, 3) uint8 BGR ``ndarray``, shared by every reader, never copied),
``detections`` (list of Detection), ``nav`` (AeroNavigation), ``odometry`` (Odometry dict) or ``value``;
``meta`` is the FrameMeta of the frame the item derives from; ``robot`` the robot it belongs to; ``trace``
accumulates the per-frame timings used for latency accounting (``capture_wall``: ``time.time()`` when the frame
was ready, ``inference_ms``, ``post_ms``). A lock-step envelope also carries its :class:`~.host.Cascade`
(``tok``).
"""
from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

import numpy as np

from aerodaas.config import RobotConfig, SimulationConfig, WorldConfig
from aerodaas.models import AeroNavigation, CameraIntrinsics, Detection, FrameMeta, FramePose, Waypoint
from aerodaas.safety import SafetyViolation

from .host import Cascade, Component, Host


def _kind_of(out: Any) -> str:
    if isinstance(out, AeroNavigation):
        return "nav"
    if isinstance(out, list) and (not out or isinstance(out[0], Detection)):
        return "detections"
    return "value"


def _percentiles(values: list[float]) -> dict[str, float]:
    a = np.asarray(values if values else [0.0], float)
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "n": len(values)}


# --------------------------------------------------------------------------------------------------- camera
class CameraComponent:
    """A camera sensor. :meth:`capture` (run on the host's pool when the clock says a frame is due) produces one
    frame — rendered by the simulator at the drone's pose (``source: sim``), the backend's own newest frame
    (``source: backend``, e.g. a Tello), or the recorded frame at this time of an MCAP recording's camera channel
    (``source: mcap``, to re-run analytics on a recorded flight) — makes it read-only, and publishes it. While the previous capture is still being
    rendered a new one is skipped and counted (``dropped_at_camera``). Frames go to the recorder by reference."""

    kind = "camera"

    def __init__(self, host: Host, cid: str, robot_id: str, sensor_id: str, props: dict, world: Any,
                 backend: Any, recorder: Any, epoch_ns: int) -> None:
        self.host, self.cid = host, cid
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
        self.host.submit(self._capture, position, yaw, t, self.ticks, tok, time.perf_counter())
        return True

    def _capture(self, position: tuple, yaw: float, t: float, seq: int, tok: Cascade | None, ticked: float) -> None:
        self.dispatch_ms.append((time.perf_counter() - ticked) * 1e3)
        try:
            try:
                env = self._produce(position, yaw, t, seq)
            finally:
                self._busy.release()  # the next frame may be rendered while this one travels downstream
            if env is not None:
                self.host.publish(self.cid, [env], tok, inline=True)
        finally:
            if tok is not None:
                tok.done()

    def capture(self, position: tuple, yaw: float, t: float, seq: int, tok: Cascade | None = None) -> np.ndarray | None:
        """Produce one frame and hand it to the subscribers in this thread; returns it (None if the source had no
        new frame)."""
        env = self._produce(position, yaw, t, seq)
        if env is None:
            return None
        self.host.publish(self.cid, [env], tok, inline=True)
        return env["data"]

    def _produce(self, position: tuple, yaw: float, t: float, seq: int) -> dict | None:
        """Render (or fetch) the frame, make it read-only, record it; returns its envelope."""
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
        self.host.copies.count("materialised")
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
        return {"kind": "frame", "data": frame, "meta": meta, "sim_t": t, "robot": self.robot_id,
                "trace": {"capture_wall": wall, "inference_ms": 0.0, "post_ms": 0.0}}

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
                "outlets": self.host.outlet_stats(self.cid), "subscribers": len(self.host.routes.get(self.cid, []))}


# --------------------------------------------------------------------------------------------------- analytics
class AnalyticsComponent(Component):
    """Hosts one analytics (IAnalyse / INavigableAnalyse) object: ``setup()`` once, then ``process()`` on every
    delivered item; non-None outputs are recorded and published. An item older than the newest one already
    processed from the same source (possible when two pool threads race) is skipped as stale."""

    kind = "analytics"

    def __init__(self, host: Host, cid: str, name: str, analytics: Any, recorder: Any, epoch_ns: int,
                 buffer: int = 1) -> None:
        super().__init__(host, cid, buffer)
        self.name = name
        self.obj = analytics
        self.obj.setup()
        self.recorder = recorder
        self.epoch_ns = epoch_ns
        self.processed = 0
        self.outputs = 0
        self.stale = 0
        self.latest: Any = None
        self.proc_ms: list[float] = []
        self._newest: dict[tuple, float] = {}
        self.failures = 0  # items whose process() raised
        self.last_failure: str | None = None
        self.on_error = getattr(analytics, "on_error", "continue")  # continue | abort (checked before Ray)
        self.aborted = False

    def handle(self, port: str, env: dict) -> list[dict] | None:
        meta = env.get("meta")
        if meta is not None:
            key = (meta.robot_id, meta.sensor_id)
            if meta.capture_time < self._newest.get(key, -1.0):
                self.stale += 1
                return None
            self._newest[key] = meta.capture_time
        t0 = time.perf_counter()
        try:
            out = self.obj.process(env["data"], meta)
        except Exception as e:  # noqa: BLE001 - the analytics' own bug: logged, recorded, counted, policy applied
            self._failed(e, env)
            return None
        dt_ms = (time.perf_counter() - t0) * 1e3
        return self._emit(out, env, dt_ms, getattr(self.obj, "last_timing", None))

    def _failed(self, e: Exception, env: dict) -> None:
        """An exception in ``process``: logged with its traceback (the first 5, then every 100th), recorded as an
        ``analytics_error`` event of the robot, counted in the run's summary; ``on_error == "abort"`` ends every
        mission of the run as failed (once)."""
        import logging
        import traceback

        self.failures += 1
        tb = traceback.format_exc()
        self.last_failure = f"{type(e).__name__}: {e}"
        if self.failures <= 5 or self.failures % 100 == 0:
            logging.getLogger("aerodaas.analytics").error("analytics %r failed on item %d (%d failures so far):\n%s",
                                                          self.name, self.processed + self.failures, self.failures, tb)
        meta = env.get("meta")
        robot = env.get("robot") or (meta.robot_id if meta is not None else "?")
        if self.recorder is not None:
            self.recorder.json(f"/{robot}/events", self.epoch_ns + int(env.get("sim_t", 0.0) * 1e9),
                               {"robot": robot, "t": env.get("sim_t", 0.0), "event": "analytics_error",
                                "analytics": self.name, "error": self.last_failure, "traceback": tb,
                                "count": self.failures, "on_error": self.on_error}, "aerodaas.MissionEvent")
        if self.on_error == "abort" and not self.aborted:
            self.aborted = True
            abort = getattr(self, "abort", None)
            if callable(abort):
                abort(f"analytics {self.name!r} raised {self.last_failure} (on_error=abort)")

    def _emit(self, out: Any, env: dict, dt_ms: float, timing: dict | None) -> list[dict] | None:
        """Count one processed item that took ``dt_ms`` (ms) and, for a non-None output, record it and return the
        envelope to publish; ``timing["inference_ms"]`` (if given) splits ``dt_ms`` into inference and
        post-processing in the latency trace."""
        meta = env.get("meta")
        self.proc_ms.append(dt_ms)
        self.processed += 1
        self.host.mark_processed()
        if out is None:
            return None
        self.outputs += 1
        self.latest = out
        trace = dict(env.get("trace") or {})
        if timing and "inference_ms" in timing:
            trace["inference_ms"] = trace.get("inference_ms", 0.0) + timing["inference_ms"]
            trace["post_ms"] = trace.get("post_ms", 0.0) + dt_ms - timing["inference_ms"]
        else:
            trace["post_ms"] = trace.get("post_ms", 0.0) + dt_ms
        kind = _kind_of(out)
        robot = env.get("robot") or (meta.robot_id if meta is not None else "?")
        if self.recorder is not None:
            t_ns = self.epoch_ns + int(env.get("sim_t", 0.0) * 1e9)
            if kind == "detections":
                size = (meta.intrinsics.width, meta.intrinsics.height) if meta else None
                self.recorder.detections(f"/{robot}/{self.name}/detections", t_ns, out, size)
            elif kind == "nav":
                self.recorder.json(f"/{robot}/{self.name}/navigation", t_ns, out.model_dump(mode="json"),
                                   "aerodaas.AeroNavigation")
            elif isinstance(out, dict):
                self.recorder.json(f"/{robot}/{self.name}", t_ns, out, "aerodaas.AnalyticsOutput")
        return [{"kind": kind, "data": out, "meta": meta, "sim_t": env.get("sim_t", 0.0), "trace": trace,
                 "robot": robot}]

    def get_latest(self) -> Any:
        return self.latest

    def stats(self) -> dict:
        p = np.array(self.proc_ms or [0.0])
        out = {"name": self.name, "processed": self.processed, "outputs": self.outputs, "stale": self.stale,
               "process_ms_median": float(np.median(p)), **self.mailbox_stats(),
               "failures": self.failures, "last_failure": self.last_failure, "on_error": self.on_error,
               "outlets": self.host.outlet_stats(self.cid)}
        extra = getattr(self.obj, "stats", None)
        if callable(extra):
            out.update(extra())
        return out


class ScheduledAnalyticsComponent(AnalyticsComponent):
    """An analytics whose frames the *analytics scheduler* places (the paper's setAnalyticsScheduler): every frame
    delivered to it becomes a task — (drone, this analytics as the model, the frame, arrival now, deadline from its
    QoS) — that :class:`AnalyticsSchedulingService`'s policy runs on the edge (here, on the frame object itself), sends
    to the cloud (as JPEG, with the FrameMeta) or drops with a reason. A result that is done by its deadline is
    recorded and published downstream exactly as an unscheduled analytics' output; a late one earns nothing and is
    only counted. Every task's outcome is recorded on ``/<robot>/<name>/tasks``. The mailbox only hands frames to the
    scheduler (microseconds), so it never drops: dropping is the scheduler's decision, with its reason."""

    def __init__(self, host: Host, cid: str, name: str, analytics: Any, recorder: Any, epoch_ns: int,
                 service: "AnalyticsSchedulingService") -> None:
        super().__init__(host, cid, name, analytics, recorder, epoch_ns, buffer=256)
        self.service = service
        self.outcomes: dict[str, int] = {}
        #: executed tasks (done on time or late) per tier, and those whose result was non-empty (e.g. detections)
        self.executed: dict[str, int] = {}
        self.with_output: dict[str, int] = {}

    def handle(self, port: str, env: dict) -> None:
        frame = env.get("data")
        if not (isinstance(frame, np.ndarray) and frame.ndim == 3):
            raise TypeError(f"scheduled analytics {self.name!r} takes camera frames ((H, W, 3) uint8 BGR), got "
                            f"{type(frame).__name__}")
        tok = env.get("tok")
        if tok is not None:
            tok.add()  # held until the task's terminal state (on_task_done)
        try:
            self.service.submit(self, env)
        except Exception:
            if tok is not None:
                tok.done()
            raise
        return None

    def on_task_done(self, task: Any) -> None:
        """Called by the dispatcher (its loop thread) once per task, in its terminal state: publish an on-time
        result, record the outcome, release the lock-step hold."""
        env = task.payload.context
        tok = env.get("tok")
        try:
            state = task.state.value
            self.outcomes[state] = self.outcomes.get(state, 0) + 1
            if state in ("done_on_time", "done_late"):  # the model ran, on the edge or in the cloud
                tier = task.tier or "edge"
                self.executed[tier] = self.executed.get(tier, 0) + 1
                self.with_output[tier] = self.with_output.get(tier, 0) + bool(task.result)
            robot = env.get("robot") or task.drone
            if self.recorder is not None:
                t_ns = self.epoch_ns + int(env.get("sim_t", 0.0) * 1e9)
                rec = {"task_id": task.task_id, "model": task.model, "state": state, "tier": task.tier,
                       "reason": task.reason, "arrival_ms": task.arrival_ms, "deadline_ms": task.deadline_ms,
                       "start_ms": task.start_ms, "end_ms": task.end_ms}
                self.recorder.json(f"/{robot}/{self.name}/tasks", t_ns, rec, "aerodaas.AnalyticsTask")
            if state == "done_on_time":
                dt_ms = (task.end_ms - task.start_ms) if task.start_ms is not None and task.end_ms is not None else 0.0
                timing = task.notes.get("timing") if task.tier == "edge" else {"inference_ms": dt_ms}
                envs = self._emit(task.result, env, dt_ms, timing)
                if envs:
                    self.host.publish(self.cid, envs, tok)
        except Exception as e:  # never lose the hold or the dispatcher's loop over one bad result
            self.errors += 1
            self.host.report_error(self.cid, e)
        finally:
            if tok is not None:
                tok.done()

    def stats(self) -> dict:
        out = super().stats()
        out["scheduled"] = {"scheduler": self.service.name, "outcomes": dict(self.outcomes),
                            "executed": dict(self.executed), "with_output": dict(self.with_output)}
        if "frames_with_detections" in out:  # the edge copy's own counts miss the frames the cloud served
            out["frames"] = sum(self.executed.values())
            out["frames_with_detections"] = sum(self.with_output.values())
            out["frames_by_tier"] = dict(self.executed)
        return out


class AnalyticsSchedulingService:
    """The edge device's analytics scheduler, inside the edge host: one :class:`aerodaas.schedulers.dispatch.dispatcher.AnalyticsDispatcher`
    (one policy instance, one edge executor thread, the scheduler's timers) for every scheduled analytics of the
    host, each analytics being one *model* of the workload. Edge tasks run the host's own analytics objects on the
    camera's frame (no copy); cloud tasks go to ``CloudExecutor`` actors (tier=cloud) that run copies of the same
    analytics on the JPEG. A cloud executor that dies (its node lost) is handled by the pool: in-flight tasks are
    retried or FAILED, the policy is told when no cloud is left, and the mission goes on.

    ``spec``: ``{"name", "workload" (Workload), "executors" ([CloudExecutorActor handles], may be empty),
    "network" ([NetworkModel specs]), "jpeg_quality", "seed"}``."""

    def __init__(self, host: Host, spec: dict) -> None:
        self.host = host
        self.spec = spec
        self.name = spec["name"]
        self.comps: dict[str, ScheduledAnalyticsComponent] = {}
        self.dispatcher = None
        self.final: dict | None = None

    def add(self, comp: ScheduledAnalyticsComponent) -> None:
        if comp.name in self.comps:
            raise ValueError(f"two scheduled analytics are named {comp.name!r}; give them distinct names")
        self.comps[comp.name] = comp

    def start(self) -> None:
        from aerodaas.schedulers.dispatch.banks import AnalyticsBank
        from aerodaas.schedulers.dispatch.cloud_pool import CloudPool
        from aerodaas.schedulers.dispatch.dispatcher import AnalyticsDispatcher
        from aerodaas.schedulers.dispatch.edge_executors import AnalyticsEdgeExecutor
        from aerodaas.schedulers.dispatch.emulation import NetworkModel
        from aerodaas.schedulers.analytics_base import make_analytics_scheduler

        w = self.spec["workload"]
        policy = make_analytics_scheduler(self.name, w)
        bank = AnalyticsBank({n: c.obj for n, c in self.comps.items()}, shared=True)
        ex = list(self.spec.get("executors") or [])
        pool = CloudPool(ex, mode="real", network=NetworkModel.parse(self.spec.get("network") or ["none"],
                                                                     seed=int(self.spec.get("seed", 0))),
                         jpeg_quality=int(self.spec.get("jpeg_quality", 90))) if ex else None
        self.dispatcher = AnalyticsDispatcher(policy, AnalyticsEdgeExecutor(bank), pool, edge_id=self.host.host_id,
                                              on_result=self._on_result, keep_tasks=False)
        self.dispatcher.start_background()

    def submit(self, comp: ScheduledAnalyticsComponent, env: dict) -> None:
        from aerodaas.schedulers.dispatch.payload import FramePayload

        meta = env.get("meta")
        drone = env.get("robot") or (meta.robot_id if meta is not None else "?")
        self.dispatcher.submit(drone, comp.name, FramePayload(env["data"], meta, env))

    def _on_result(self, task: Any) -> None:
        self.comps[task.model].on_task_done(task)

    def report(self) -> dict:
        """The dispatcher's report (utility, states, drops by reason, decision latency, cloud losses): final after
        :meth:`finish`, else the run so far."""
        if self.final is not None:
            return self.final
        rep = self.dispatcher.report() if self.dispatcher is not None else {}
        if self.dispatcher is not None and self.dispatcher.cloud is not None:
            rep["cloud"] = self.dispatcher.cloud.report()
        return rep

    def finish(self) -> dict:
        """End the run: tasks still held end with a reason (every task reaches one terminal state); idempotent."""
        if self.final is None and self.dispatcher is not None:
            self.final = self.dispatcher.finish_background()
        return self.final or {}


# --------------------------------------------------------------------------------------------------- scheduler
class SchedulerComponent(Component):
    """Hosts one robot's trajectory scheduler (the paper's INavigate plug-in) and its waypoint priority queue.

    The drone calls :meth:`tick` / :meth:`complete` / :meth:`discard` directly (same host, no actor hop);
    analytics streams deliver navigation as envelopes on port ``priority:<n>[:replace]``; users add navigation
    through :meth:`add_navigation` (the HITL API). Everything added is checked by the robot's
    :class:`~aerodaas.safety.SafetyGate` first (all items or none). New navigation nudges the drone, which applies
    it at once; the per-frame latency (frame ready -> command applied to the vehicle) is measured here. The
    waypoint plan is recorded on ``/<robot>/mission/plan`` at start and whenever the queued waypoints change."""

    kind = "scheduler"

    def __init__(self, host: Host, cid: str, robot_id: str, scheduler: Any, recorder: Any, epoch_ns: int,
                 robot_cfg: dict | None = None) -> None:
        from aerodaas.safety import SafetyGate

        super().__init__(host, cid, buffer=4)
        self.robot_id = robot_id
        self.s = scheduler
        self.recorder = recorder
        self.epoch_ns = epoch_ns
        self.position = tuple(scheduler.start)
        self.now = 0.0
        self.latency: list[dict] = []
        cfg = RobotConfig.model_validate(robot_cfg) if robot_cfg else RobotConfig(id=robot_id)
        self.home = cfg.home
        self.gate = SafetyGate(cfg.safety, cfg.limits, cfg.home, control_period_s=1.0 / cfg.control_rate_hz)
        self.max_per_request = cfg.max_waypoints_per_request
        self.max_queued = cfg.max_queued_items
        self._plan_lock = threading.Lock()  # one planner at a time; never the lock the control tick takes
        self.refused: list[dict] = []
        self.discarded: list[dict] = []
        self._plan_sig: Any = None
        self._replaced: set[str] = set()
        self.drone: Any = None  # the DroneComponent, set by the host runtime

    def tick(self, now: float, position: tuple) -> dict:
        self.now, self.position = now, tuple(position)
        if self._plan_sig is None:
            self._record_plan()
        cur = self.s.current(now)
        left = self.s.pending(distance_driven_only=True)
        if cur is None:
            return {"item": None, "preplanned_left": left}
        m, item = cur
        return {"item": item, "priority": m.priority, "mission": m.name, "preplanned_left": left}

    def queued(self) -> list:
        """Every queued item in flying order (see :meth:`TrajectoryScheduler.queued`)."""
        return self.s.queued()

    def pending(self) -> int:
        """Queued items of pre-planned (distance-driven) missions."""
        return self.s.pending(distance_driven_only=True)

    def complete(self, item_id: str) -> bool:
        ok = self.s.complete(item_id)
        self._record_plan()
        return ok

    def discard(self, item_id: str, reason: str) -> bool:
        """Drop the head item ``item_id`` without counting it as visited (rejected by safety, or an executed
        action). Returns False if no mission has it at its head."""
        if not self.s.discard(item_id):
            return False
        self.discarded.append({"id": item_id, "t": self.now, "reason": reason})
        self._record_plan()
        return True

    def _event(self, event: str, **kw: Any) -> None:
        if self.recorder is not None:
            self.recorder.json(f"/{self.robot_id}/events", self.epoch_ns + int(self.now * 1e9),
                               {"robot": self.robot_id, "t": self.now, "event": event, **kw}, "aerodaas.MissionEvent")

    def handle(self, port: str, env: dict) -> None:
        from aerodaas.safety import SafetyViolation

        parts = port.split(":")
        prio = int(parts[1]) if parts[0] == "priority" else None
        nav = env["data"]
        if not isinstance(nav, AeroNavigation) or env.get("robot", self.robot_id) != self.robot_id:
            return None  # a shared analytics navigates each robot through that robot's own scheduler
        replace = "replace" in parts[2:] and port not in self._replaced
        try:
            self._check_bounds(nav, ignore_queue=replace)
            nav = self.gate.check_navigation(nav, self.position)
            if replace:
                self._replaced.add(port)  # pattern 5: the first navigation from this source aborts the queued missions
                self.s.clear_navigation()
                self.discarded.append({"id": "*", "t": self.now, "reason": f"mission aborted by {port}"})
                self._event("mission_aborted", by=port)
            self._plan_and_add(nav, None, prio)
        except (SafetyViolation, ValueError) as e:  # an analytics asked for something unsafe: refuse it, keep running
            self.refused.append({"t": env.get("sim_t", 0.0), "source": "analytics", "error": str(e)})
            self._event("navigation_refused", source="analytics", error=str(e))
            return None
        if any(isinstance(w, Waypoint) for w in nav.waypoints) or "replace" in parts[2:]:
            self._record_plan()
        applied = self.drone.nudge() if self.drone is not None else False  # applied now, not at the next tick
        tr = env.get("trace") or {}
        if "capture_wall" in tr:
            e2e = (time.time() - tr["capture_wall"]) * 1e3
            rec = {"robot": self.robot_id, "t": env.get("sim_t", 0.0), "e2e_ms": e2e, "applied": applied,
                   "inference_ms": tr.get("inference_ms", 0.0), "post_ms": tr.get("post_ms", 0.0),
                   "overhead_ms": max(0.0, e2e - tr.get("inference_ms", 0.0) - tr.get("post_ms", 0.0))}
            self.latency.append(rec)
            if self.recorder is not None:
                self.recorder.json(f"/{self.robot_id}/latency", self.epoch_ns + int(rec["t"] * 1e9), rec,
                                   "aerodaas.FrameLatency")
        return None

    def add_navigation(self, nav: Any, index: int | None = None, priority: int | None = None) -> dict:
        """Add navigation (user or application side). Raises SafetyViolation / IndexError / TypeError and then
        changes nothing; returns the queue snapshot on success."""
        nav_, prio = self.s._unwrap(nav, priority)
        self._check_bounds(nav_)
        nav_ = self.gate.check_navigation(nav_, self.position)
        self._plan_and_add(nav_, index, prio)
        self._record_plan()
        if self.drone is not None:
            self.drone.nudge()
        return {"queued": self.s.snapshot(), "position": list(self.position), "t": self.now}

    def _check_bounds(self, nav: AeroNavigation, ignore_queue: bool = False) -> None:
        """Bounded work: at most ``max_waypoints_per_request`` items per request and ``max_queued_items`` queued in
        all (robot config). Raises ValueError naming the limit; nothing is planned or queued."""
        n = len(nav.waypoints)
        if n > self.max_per_request:
            raise ValueError(f"waypoints: {n} items in one request, more than max_waypoints_per_request "
                             f"({self.max_per_request}) of robot {self.robot_id!r}")
        queued = 0 if ignore_queue else self.s.pending()
        if queued + n > self.max_queued:
            raise ValueError(f"waypoints: {queued} items queued + {n} new exceed max_queued_items "
                             f"({self.max_queued}) of robot {self.robot_id!r}")

    def _plan_and_add(self, nav: AeroNavigation, index: int | None, prio: int) -> None:
        """Add ``nav`` (already through the gate) at ``prio``: planned on a copy of the queue, outside the lock the
        drone's control tick takes (a long re-plan never holds the tick), then every leg of the resulting tour of
        that mission, from the drone's position, is checked against the geofence (SafetyViolation naming the leg:
        nothing is queued, never a silent drop in flight), and the plan is committed under the lock, keeping what
        happened meanwhile (waypoints reached or discarded, navigation added by others)."""
        from aerodaas.schedulers.base import Mission

        with self._plan_lock:
            position = self.position
            with self.s._lock:
                snap = [Mission(m.priority, m.seq, m.name, list(m.items), m.distance_driven, dict(m.segment_of))
                        for m in self.s._missions]
                cur = self.s._find(prio)
                if index is not None and index > (len(cur.items) if cur is not None else 0):
                    raise IndexError(f"index: {index} is out of range for the priority-{prio} mission of "
                                     f"{len(cur.items) if cur is not None else 0} items")
            twin = self.s.fork(snap)
            twin.add_navigation(nav, index=index, priority=prio, position=position)  # the planning
            planned = twin._find(prio)
            self._check_tour(planned.items if planned is not None else [], position)
            added = {id(i) for i in nav.waypoints}
            with self.s._lock:
                real = self.s._find(prio)
                alive = {id(i) for i in real.items} if real is not None else set()
                in_plan = {id(i) for i in planned.items}
                items = [i for i in planned.items if id(i) in alive or id(i) in added]
                items += [i for i in (real.items if real is not None else []) if id(i) not in in_plan]
                tags = [planned.segment_of.get(id(i), real.segment_of.get(id(i), 0) if real is not None else 0)
                        for i in items]
                issued = getattr(twin, "_segments_issued", 0)
                if issued > getattr(self.s, "_segments_issued", 0):
                    self.s._segments_issued = issued
                if real is None:
                    self.s._seq += 1
                    real = Mission(prio, self.s._seq, planned.name, [], planned.distance_driven)
                    self.s._missions.append(real)
                real.items = items
                real.set_segment_ids(tags)

    def _check_tour(self, items: list, position: tuple) -> None:
        """Every leg of a planned tour (from ``position`` through its waypoints, ENU metres) against the geofence."""
        fence = self.gate.fence
        if fence.is_empty:
            return
        prev, prev_id = (float(position[0]), float(position[1])), "the drone's position"
        for w in items:
            if not isinstance(w, Waypoint):
                continue
            x, y, _ = w.to_local(self.home)
            why = fence.check_segment(prev, (x, y))
            if why is not None:
                self.gate.rejected += 1
                raise SafetyViolation(w.id, "leg", [prev_id, w.id], f"the planned tour's leg from {prev_id} to "
                                      f"{w.id!r} is refused by the geofence: {why}")
            prev, prev_id = (x, y), repr(w.id)

    def clear_navigation(self, priority: int | None = None) -> None:
        self.s.clear_navigation(priority)
        self._record_plan()

    def snapshot(self) -> list[dict]:
        return self.s.snapshot()

    def _record_plan(self) -> None:
        """Record the queued waypoints (with local ENU targets) when they changed since the last record."""
        missions = []
        with self.s._lock:
            for m in sorted(self.s._missions, key=lambda m: (m.priority, m.seq)):
                items = [{"id": w.id, "local": [round(c, 3) for c in w.to_local(self.home)],
                          "hover_duration": w.hover_duration} for w in m.items if isinstance(w, Waypoint)]
                if items:
                    missions.append({"name": m.name, "priority": m.priority, "items": items})
        sig = [(m["name"], m["priority"], [i["id"] for i in m["items"]]) for m in missions]
        if sig == self._plan_sig:
            return
        self._plan_sig = sig
        if self.recorder is not None:
            self.recorder.json(f"/{self.robot_id}/mission/plan", self.epoch_ns + int(self.now * 1e9),
                               {"robot": self.robot_id, "t": self.now, "missions": missions}, "aerodaas.MissionPlan")

    def stats(self) -> dict:
        out: dict[str, Any] = {"completed": list(self.s.completed), "frames_with_latency": len(self.latency),
                               "refused": self.refused[-20:], "refused_count": len(self.refused),
                               "discarded": self.discarded, **self.mailbox_stats()}
        if self.latency:
            for key in ("e2e_ms", "overhead_ms", "inference_ms"):
                out[key] = _percentiles([r[key] for r in self.latency])
            out["latency_records"] = list(self.latency)
        return out


# --------------------------------------------------------------------------------------------------- runtime
class _Checkpointer:
    """Sends each drone's checkpoint (:mod:`.checkpoint`) to the run's recorder actor about every ``period_s``
    wall seconds and whenever a waypoint was completed, without waiting for the reply (fire and forget: a lost
    checkpoint only means resuming from the one before). Does nothing on an actor without the recorder peer."""

    def __init__(self, host: Host, drones: list, period_s: float = 1.0) -> None:
        self.host, self.period_s = host, period_s
        self.on = "recorder" in (getattr(host, "peers", None) or {}) and bool(drones)
        self.last = time.monotonic()
        self.visited = {id(d): len(d.visited) for d in drones}

    def maybe(self, active: list) -> None:
        if not self.on:
            return
        now = time.monotonic()
        due = now - self.last >= self.period_s
        for d in active:
            if due or len(d.visited) != self.visited.get(id(d)):
                from .checkpoint import drone_checkpoint

                self.visited[id(d)] = len(d.visited)
                try:
                    self.host.peer("recorder").checkpoint.remote(d.cfg.id, drone_checkpoint(d))
                except Exception as e:  # noqa: BLE001 - a missing checkpoint must never stop the flight
                    self.host.report_error("checkpoint", e)
                    self.on = False
        if due:
            self.last = now


class HostRuntime:
    """Builds a host's components from the driver's ``spec`` and runs them.

    ``spec`` keys: ``sim`` (SimulationConfig dict), ``world`` (WorldConfig dict, for simulated cameras),
    ``record`` ({"path", "meta"} or None: the recorder lives on the host that has the drones), ``analytics``
    ([{"cid", "name", "obj", "buffer"}]), ``robots`` ([{"robot": RobotConfig dict, "drone_cid",
    "scheduler_cid", "scheduler": TrajectoryScheduler, "preplanned": n, "cameras": [{"cid", "sensor", "props"}],
    "odom_cids": [...], "stat_cids": [...]}]). Drones connect to their vehicles here, so an unreachable vehicle
    fails the run before take-off."""

    def __init__(self, host: Host, spec: dict) -> None:
        from .drone import DroneComponent
        from .recorder import RecorderService

        self.host = host
        self.sim = SimulationConfig.model_validate(spec.get("sim") or {})
        rec = spec.get("record")
        if rec:  # the edge host: the file and/or the live view
            self.recorder = RecorderService(rec.get("path"), rec.get("meta"), copies=host.copies, live=rec.get("live"))
        elif spec.get("record_remote"):  # an actor of a recorded run: its messages go to the run's recorder actor
            from .recorder import RemoteRecorder

            self.recorder = RemoteRecorder(host, spec["record_remote"])
        else:
            self.recorder = None
        host.recorder = self.recorder
        self.comps: dict[str, Any] = {}
        self.scheduling = AnalyticsSchedulingService(host, spec["analytics_scheduler"]) \
            if spec.get("analytics_scheduler") else None
        for a in spec.get("analytics", []):
            if a.get("scheduled"):
                comp = ScheduledAnalyticsComponent(host, a["cid"], a["name"], a["obj"], self.recorder, host.epoch_ns,
                                                   self.scheduling)
                self.scheduling.add(comp)
            else:
                comp = AnalyticsComponent(host, a["cid"], a["name"], a["obj"], self.recorder, host.epoch_ns,
                                          a.get("buffer", 1))
            self.comps[a["cid"]] = host.add(comp)
        if self.scheduling is not None:
            self.scheduling.start()
        self.drones: list[DroneComponent] = []
        world = None
        for r in spec.get("robots", []):
            cfg = RobotConfig.model_validate(r["robot"])
            sched = host.add(SchedulerComponent(host, r["scheduler_cid"], cfg.id, r["scheduler"], self.recorder,
                                                host.epoch_ns, r["robot"]))
            drone = DroneComponent(r["drone_cid"], r["robot"], host, sched, self.recorder, host.epoch_ns,
                                   r["preplanned"], r["odom_cids"], r["stat_cids"])
            sched.drone = drone
            for c in r["cameras"]:
                if c["props"].get("source", "sim") == "sim" and world is None:
                    from aerodaas.sim.world import World

                    w = WorldConfig.model_validate(spec["world"])
                    world = World(w.ground, w.targets)  # one texture for every camera of this host
                cam = CameraComponent(host, c["cid"], cfg.id, c["sensor"], c["props"], world, drone.backend,
                                      self.recorder, host.epoch_ns)
                drone.cameras.append({"comp": cam, "fps": cam.fps, "next_t": 0.0})
                self.comps[c["cid"]] = cam
            self.comps[r["drone_cid"]] = drone
            self.comps[r["scheduler_cid"]] = sched
            self.drones.append(drone)
        # real cameras are not synchronised: spread the fleet's capture phases over one frame period
        for c in self.comps.values():  # on_error=abort: end every mission of the run, wherever the drones are
            if isinstance(c, AnalyticsComponent):
                c.abort = self._abort_all
        if self.recorder is not None:  # a failing disk becomes an event of every drone (and the run's report)
            self.recorder.on_failure.append(
                lambda info, drones=tuple(self.drones): [d._event("recording_failed", **info) for d in drones])
        cams = [c for d in self.drones for c in d.cameras]
        for i, c in enumerate(cams):
            c["next_t"] = i / (len(cams) * c["fps"])
        for d in self.drones:
            d.connect()

    def describe(self) -> dict:
        live = getattr(self.recorder, "live", None)
        return {"host": self.host.host_id, "tier": self.host.tier, "components": sorted(self.comps),
                "pid": __import__("os").getpid(), "threads": self.host.pool._max_workers,
                "live_url": live.url if live is not None else None}

    def lookup(self, cid: str) -> Any:
        try:
            return self.comps[cid]
        except KeyError:
            raise KeyError(f"host {self.host.host_id!r} has no component {cid!r}; it has {sorted(self.comps)}") from None

    # ------------------------------------------------------------------ the clock
    def run(self, timeout_s: float | None = None, resume: bool = False) -> dict[str, dict]:
        """Fly every drone of this host to the end of its mission; returns robot id -> report. ``resume``: the
        drones were restored from checkpoints (a restarted actor): no arming, no take-off, the mission goes on.

        One clock for the fleet: every ``1/physics_hz`` simulated seconds each backend steps (simulator) or is
        polled (real vehicles), odometry is published at its rate, due cameras capture, and each drone's control
        tick runs at ``control_rate_hz``. Time runs at ``speedup`` x wall time (lock-step: as fast as the
        analytics allow). A control tick that runs later than one control period after its due wall time (the
        period divided by ``speedup``) is counted as missed."""
        sim, drones = self.sim, self.drones
        dt = 1.0 / sim.physics_hz
        lock = sim.lockstep
        for d in drones:
            if resume and getattr(d, "restored_from", None) is not None:
                continue
            d.start()
        wall0 = time.monotonic()
        step = 0
        active = [d for d in drones if not d.done]
        checkpoints = _Checkpointer(self.host, drones)
        self.tick_lateness: list[float] = []
        try:
            while active:
                step += 1
                nominal = step * dt
                if not lock:  # simulated time ``nominal`` is computed when wall time reaches it, not one step early
                    lag = wall0 + nominal / sim.speedup - time.monotonic()
                    if lag > 0:
                        time.sleep(lag)
                tok = Cascade() if lock else None
                for d in active:
                    d.step(dt, tok)
                for d in active:
                    b = d.backend
                    for cam in d.cameras:
                        if b.t + 1e-9 >= cam["next_t"]:
                            cam["next_t"] += 1.0 / cam["fps"]
                            if b.t > cam["next_t"] + 1.0 / cam["fps"]:  # vehicle clock jumped: do not burst
                                cam["next_t"] = b.t + 1.0 / cam["fps"]
                            cam["comp"].try_capture(tuple(float(c) for c in b.position), float(b.yaw), b.t, tok)
                if tok is not None:
                    tok.wait()
                now = time.monotonic()
                finished = []
                for d in active:
                    if d.backend.t + 1e-9 >= d.next_tick:
                        due = d.next_tick
                        d.next_tick += d.tick_period
                        if not lock:
                            late = now - (wall0 + due / sim.speedup) if d.backend.clock == "sim" else 0.0
                            self.tick_lateness.append(late)
                            if late > d.tick_period / sim.speedup:
                                d.missed_ticks += 1
                        if d.control_tick():
                            finished.append(d)
                    elif d._end_req is not None and d.control_tick():
                        finished.append(d)
                for d in finished:
                    d.finish()
                    active.remove(d)
                checkpoints.maybe(active)
                if timeout_s is not None and time.monotonic() - wall0 > timeout_s:
                    for d in active:
                        d.outcome = "timeout"
                        d._event("timeout", wall_s=timeout_s)
                        d.finish()
                    active = []
        finally:
            for d in drones:
                d.close()
            if self.scheduling is not None:
                try:
                    self.scheduling.finish()
                except Exception as e:  # reported; the drones' reports must still come back
                    self.host.report_error("analytics_scheduler", e)
        return {d.cfg.id: d.report() for d in drones}

    def _abort_all(self, reason: str) -> None:
        """End every drone's mission as failed with ``reason``: this host's drones directly, the others through
        their host (an analytics on the cloud tier aborting drones on the edge)."""
        for d in self.drones:
            d.error = reason
            d.end_mission("failed")
        peers = getattr(self.host, "peers", {}) or {}
        for cid, hid in getattr(self.host, "location", {}).items():
            if cid.endswith("/drone") and hid in peers and not any(d.cid == cid for d in self.drones):
                self.host.peer(hid).call.remote(cid, "end_mission", "failed")

    # ------------------------------------------------------------------ end
    def drain(self) -> bool:
        """The drones are done: let the analytics scheduler (a dispatcher actor) finish its tasks in flight, so that
        its report counts every task in a terminal state. Returns True when there was one."""
        if self.scheduling is None:
            return False
        try:
            self.scheduling.finish()
        except Exception as e:  # reported; the report must still come back
            self.host.report_error("analytics_scheduler", e)
        return True

    def stats(self) -> dict:
        out = {cid: c.stats() for cid, c in self.comps.items() if c.kind in ("camera", "analytics", "scheduler")}
        gcp = self.host.gc_pauses_ms
        out["_host"] = {"errors": self.host.errors[-10:], "error_count": len(self.host.errors),
                        "gc_pauses": {"count": len(gcp), "max_ms": max(gcp, default=0.0)},
                        "first_processed_wall": self.host.first_processed_wall,
                        "frame_copies": self.host.copies.snapshot(),
                        "tick_lateness_ms": _percentiles([x * 1e3 for x in getattr(self, "tick_lateness", [])]),
                        # a host without the recorder (cloud): messages it could not hand to the edge recorder
                        "record_send_errors": list(getattr(self.recorder, "send_errors", []))[-5:]}
        if self.scheduling is not None:
            out["_analytics_scheduler"] = self.scheduling.report()
        return out

    def close(self) -> dict:
        if self.scheduling is not None:
            try:
                self.scheduling.finish()
            except Exception as e:  # reported, never blocks closing the recording
                self.host.report_error("analytics_scheduler", e)
        self.host.close()
        for c in self.comps.values():
            close = getattr(c.obj, "close", None) if hasattr(c, "obj") else None
            if callable(close):
                try:
                    close()
                except Exception:
                    pass
        return self.recorder.close() if self.recorder is not None else {}

    def recording_report(self) -> dict:
        """The recorder's :meth:`~.recorder.RecorderService.report` (failure, lost messages), {} without one."""
        return self.recorder.report() if self.recorder is not None else {}
