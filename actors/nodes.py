"""Ray actors for sensors, analytics and the trajectory scheduler.

Messages between actors are *envelopes*: ``{"kind", "data", "meta", "trace", "sim_t"}``. ``kind`` is
``frame`` (data = ``[ObjectRef]`` of an (H, W, 3) uint8 BGR image), ``detections`` (list of Detection),
``nav`` (AeroNavigation), ``odometry`` (Odometry dict) or ``value`` (anything else). ``meta`` is the
FrameMeta of the frame the message derives from; ``trace`` accumulates per-frame timings in ms for the
latency accounting (capture wall time, inference, post-processing).
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np
import ray

from aerodaas.models import AeroNavigation, CameraIntrinsics, Detection, FrameMeta, FramePose, Waypoint

from .streams import Outlet


def _kind_of(out: Any) -> str:
    if isinstance(out, AeroNavigation):
        return "nav"
    if isinstance(out, list) and (not out or isinstance(out[0], Detection)):
        return "detections"
    return "value"


class _Publisher:
    """Mixin: outlets to subscribers, lock-step aware."""

    def _init_pub(self, lockstep: bool) -> None:
        self.lockstep = lockstep
        self.outlets: list[Outlet] = []

    def connect(self, subscribers: list[tuple[Any, str, str, int]]) -> bool:
        """``subscribers``: (actor handle, method, port, buffer) per edge."""
        self.outlets = [Outlet(a, m, p, b, self.lockstep) for a, m, p, b in subscribers]
        return True

    def _publish(self, env: dict) -> list:
        refs = [o.send(env) for o in self.outlets]
        return [r for r in refs if r is not None]

    def stream_stats(self) -> list[dict]:
        return [o.stats() for o in self.outlets]


@ray.remote(num_cpus=0)
class CameraActor(_Publisher):
    """A simulated camera: renders the world at the drone's pose (see :mod:`aerodaas.sim.world`), puts each
    frame in the object store once, and hands the ObjectRef to every subscriber and the recorder."""

    def __init__(self, robot_id: str, sensor_id: str, props: dict, world_cfg: dict, recorder: Any,
                 epoch_ns: int, lockstep: bool = False) -> None:
        from aerodaas.config import WorldConfig
        from aerodaas.sim.world import World

        self._init_pub(lockstep)
        self.robot_id, self.sensor_id = robot_id, sensor_id
        self.k = CameraIntrinsics.from_hfov(int(props["width"]), int(props["height"]), float(props["hfov_deg"]))
        self.pitch = float(props["pitch_deg"])
        self.world = World(**{k: v for k, v in WorldConfig.model_validate(world_cfg)})
        self.recorder = recorder
        self.rec_outlet = Outlet(recorder, "image", f"/{robot_id}/camera/{sensor_id}", 2) if recorder else None
        self.epoch_ns = epoch_ns
        self.frames = 0
        self.render_ms: list[float] = []
        self.latest: tuple | None = None

    def capture(self, port: str, position: tuple, yaw: float, t: float, seq: int) -> list:
        t0 = time.perf_counter()
        wall = time.time()
        pose = FramePose(position=tuple(position), yaw=yaw, camera_pitch=self.pitch)
        frame, truth = self.world.render(pose, self.k, t)
        ref = ray.put(frame)
        self.render_ms.append((time.perf_counter() - t0) * 1e3)
        self.frames += 1
        meta = FrameMeta(robot_id=self.robot_id, sensor_id=self.sensor_id, seq=seq, capture_time=t, wall_time=wall,
                         pose=pose, intrinsics=self.k)
        self.latest = (ref, meta)
        t_ns = self.epoch_ns + int(t * 1e9)
        if self.recorder is not None:
            self.rec_outlet.send(t_ns, [ref], f"{self.robot_id}/{self.sensor_id}")
            if truth:
                self.recorder.json.remote("/world/targets", t_ns, {"robot": self.robot_id, "seq": seq, "t": t,
                                                                   "targets": truth}, "aerodaas.GroundTruth")
        env = {"kind": "frame", "data": [ref], "meta": meta, "sim_t": t,
               "trace": {"capture_wall": wall, "inference_ms": 0.0, "post_ms": 0.0}}
        return self._publish(env)

    def get_latest(self) -> tuple | None:
        """(ObjectRef list, FrameMeta) of the newest frame, for pull-style access."""
        return ([self.latest[0]], self.latest[1]) if self.latest else None

    def stats(self) -> dict:
        r = np.array(self.render_ms or [0.0])
        return {"frames": self.frames, "render_ms_median": float(np.median(r)),
                "recorder_dropped": self.rec_outlet.dropped if self.rec_outlet else 0,
                "outlets": self.stream_stats()}


@ray.remote(num_cpus=0)
class AnalyticsActor(_Publisher):
    """Hosts one analytics (IAnalyse / INavigableAnalyse) object; runs ``setup()`` once, then ``process()``
    on every delivered item, and publishes non-None outputs."""

    def __init__(self, name: str, robot_id: str, analytics: Any, recorder: Any, epoch_ns: int,
                 lockstep: bool = False) -> None:
        self._init_pub(lockstep)
        self.name, self.robot_id = name, robot_id
        self.obj = analytics
        self.obj.setup()
        self.recorder = recorder
        self.epoch_ns = epoch_ns
        self.processed = 0
        self.outputs = 0
        self.latest: Any = None
        self.proc_ms: list[float] = []

    def ready(self) -> bool:
        return True

    def push(self, port: str, env: dict) -> list | None:
        data = env["data"]
        if env["kind"] == "frame":
            data = ray.get(data[0])
        t0 = time.perf_counter()
        out = self.obj.process(data, env.get("meta"))
        dt_ms = (time.perf_counter() - t0) * 1e3
        self.proc_ms.append(dt_ms)
        self.processed += 1
        if out is None:
            return []
        self.outputs += 1
        self.latest = out
        trace = dict(env.get("trace") or {})
        timing = getattr(self.obj, "last_timing", None)
        if timing and "inference_ms" in timing:
            trace["inference_ms"] = trace.get("inference_ms", 0.0) + timing["inference_ms"]
            trace["post_ms"] = trace.get("post_ms", 0.0) + dt_ms - timing["inference_ms"]
        else:
            trace["post_ms"] = trace.get("post_ms", 0.0) + dt_ms
        kind = _kind_of(out)
        t_ns = self.epoch_ns + int(env.get("sim_t", 0.0) * 1e9)
        if self.recorder is not None:
            if kind == "detections":
                meta = env.get("meta")
                size = (meta.intrinsics.width, meta.intrinsics.height) if meta else None
                self.recorder.detections.remote(f"/{self.robot_id}/{self.name}/detections", t_ns, out, size)
            elif kind == "nav":
                self.recorder.json.remote(f"/{self.robot_id}/{self.name}/navigation", t_ns,
                                          out.model_dump(mode="json"), "aerodaas.AeroNavigation")
            elif isinstance(out, dict):
                self.recorder.json.remote(f"/{self.robot_id}/{self.name}", t_ns, out, "aerodaas.AnalyticsOutput")
        new = {"kind": kind, "data": out, "meta": env.get("meta"), "sim_t": env.get("sim_t", 0.0), "trace": trace}
        return self._publish(new)

    def get_latest(self) -> Any:
        return self.latest

    def stats(self) -> dict:
        p = np.array(self.proc_ms or [0.0])
        out = {"name": self.name, "processed": self.processed, "outputs": self.outputs,
               "process_ms_median": float(np.median(p)), "outlets": self.stream_stats()}
        extra = getattr(self.obj, "stats", None)
        if callable(extra):
            out.update(extra())
        return out


@ray.remote(num_cpus=0, max_concurrency=4)
class SchedulerActor:
    """Hosts one robot's trajectory scheduler (INavigate plug-in) and its waypoint priority queue.

    The drone polls :meth:`tick` at its control rate; analytics streams deliver navigation via :meth:`push`
    on port ``priority:<n>``; users add navigation via :meth:`add_navigation` (the HITL API). Everything added
    is checked by the robot's :class:`~aerodaas.safety.SafetyGate` first (all items or none). Per-frame latency
    (capture -> command queued) is measured here. The waypoint plan is recorded on ``/<robot>/mission/plan``
    at start and whenever the queued waypoints change."""

    def __init__(self, robot_id: str, scheduler: Any, recorder: Any, epoch_ns: int,
                 robot_cfg: dict | None = None) -> None:
        from aerodaas.config import RobotConfig
        from aerodaas.safety import SafetyGate

        self.robot_id = robot_id
        self.s = scheduler
        self.recorder = recorder
        self.epoch_ns = epoch_ns
        self.position = tuple(scheduler.start)
        self.now = 0.0
        self.latency: list[dict] = []
        cfg = RobotConfig.model_validate(robot_cfg) if robot_cfg else RobotConfig(id=robot_id)
        self.home = cfg.home
        self.gate = SafetyGate(cfg.safety, cfg.limits, cfg.home)
        self.refused: list[dict] = []
        self.discarded: list[dict] = []
        self._plan_sig: Any = None
        self._replaced: set[str] = set()

    def tick(self, now: float, position: tuple) -> dict | None:
        self.now, self.position = now, tuple(position)
        if self._plan_sig is None:
            self._record_plan()
        cur = self.s.current(now)
        left = self.s.pending(distance_driven_only=True)
        if cur is None:
            return {"item": None, "preplanned_left": left}
        m, item = cur
        return {"item": item, "priority": m.priority, "mission": m.name, "preplanned_left": left}

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

    def push(self, port: str, env: dict) -> list:
        from aerodaas.safety import SafetyViolation

        parts = port.split(":")
        prio = int(parts[1]) if parts[0] == "priority" else None
        nav = env["data"]
        if not isinstance(nav, AeroNavigation):
            return []
        try:
            nav = self.gate.check_navigation(nav, self.position)
        except SafetyViolation as e:  # an analytics asked for something unsafe: refuse it, keep running
            self.refused.append({"t": env.get("sim_t", 0.0), "source": "analytics", "error": str(e)})
            if self.recorder is not None:
                self.recorder.json.remote(f"/{self.robot_id}/events", self.epoch_ns + int(self.now * 1e9),
                                          {"robot": self.robot_id, "t": self.now, "event": "navigation_refused",
                                           "source": "analytics", "error": str(e)}, "aerodaas.MissionEvent")
            return []
        if "replace" in parts[2:] and port not in self._replaced:
            self._replaced.add(port)  # pattern 5: the first navigation from this source aborts the queued missions
            self.s.clear_navigation()
            self.discarded.append({"id": "*", "t": self.now, "reason": f"mission aborted by {port}"})
            if self.recorder is not None:
                self.recorder.json.remote(f"/{self.robot_id}/events", self.epoch_ns + int(self.now * 1e9),
                                          {"robot": self.robot_id, "t": self.now, "event": "mission_aborted",
                                           "by": port}, "aerodaas.MissionEvent")
        self.s.add_navigation(nav, priority=prio, position=self.position)
        if any(isinstance(w, Waypoint) for w in nav.waypoints) or "replace" in parts[2:]:
            self._record_plan()
        tr = env.get("trace") or {}
        if "capture_wall" in tr:
            e2e = (time.time() - tr["capture_wall"]) * 1e3
            rec = {"robot": self.robot_id, "t": env.get("sim_t", 0.0), "e2e_ms": e2e,
                   "inference_ms": tr.get("inference_ms", 0.0), "post_ms": tr.get("post_ms", 0.0),
                   "overhead_ms": max(0.0, e2e - tr.get("inference_ms", 0.0) - tr.get("post_ms", 0.0))}
            self.latency.append(rec)
            if self.recorder is not None:
                self.recorder.json.remote(f"/{self.robot_id}/latency", self.epoch_ns + int(rec["t"] * 1e9), rec,
                                          "aerodaas.FrameLatency")
        return []

    def add_navigation(self, nav: Any, index: int | None = None, priority: int | None = None) -> dict:
        """Add navigation (user or application side). Raises SafetyViolation / IndexError / TypeError and then
        changes nothing; returns the queue snapshot on success."""
        nav_, prio = self.s._unwrap(nav, priority)
        nav_ = self.gate.check_navigation(nav_, self.position)
        self.s.add_navigation(nav_, index=index, priority=prio, position=self.position)
        self._record_plan()
        return {"queued": self.s.snapshot(), "position": list(self.position), "t": self.now}

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
            self.recorder.json.remote(f"/{self.robot_id}/mission/plan", self.epoch_ns + int(self.now * 1e9),
                                      {"robot": self.robot_id, "t": self.now, "missions": missions},
                                      "aerodaas.MissionPlan")

    def stats(self) -> dict:
        out: dict[str, Any] = {"completed": list(self.s.completed), "frames_with_latency": len(self.latency),
                               "refused": self.refused[-20:], "refused_count": len(self.refused),
                               "discarded": self.discarded}
        if self.latency:
            for key in ("e2e_ms", "overhead_ms", "inference_ms"):
                v = np.array([r[key] for r in self.latency])
                out[key] = {"median": float(np.median(v)), "p99": float(np.percentile(v, 99))}
        return out
