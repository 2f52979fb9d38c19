"""The naive Ray peer of ``aerodaas bench overhead``: the same pipeline (see :mod:`aerodaas.bench.pipeline`) written
as a careless user would write it on Ray — one actor per component (camera, detector, follow, scheduler, drone),
and per hop a ``ray.put`` of the payload plus a fire-and-forget actor call to the next component:

    camera.run() --ray.put(frame, meta, trace)--> detector.process --ray.put(dets, ...)--> follow.process
      --ray.put(nav, ...)--> scheduler.process --ray.put(item, ...)--> drone.apply (records the row)

The camera paces itself at 30 FPS inside one long-running method (a frame that would start late is skipped, as a
camera would). It renders at the hover pose: there is no pose feedback from the drone actor (that would be one
more hop per frame, which this pipeline is not about). Every actor is ``num_cpus=0`` so it fits next to the
AeroDaaS runtime in one local Ray. Each row carries the hop latencies (``hop_<from>_<to>``, seconds: the sender's
``ray.put`` start to the receiver's method start).
"""
from __future__ import annotations

import time
from typing import Any

import ray

from aerodaas.bench.pipeline import (FPS, HOVER_M, CameraStage, CommandStage, DetectStage, DroneStage, FollowStage, Pacer,
                       parsed_config)


class CameraActor:
    def __init__(self, width: int, height: int, kind: str, nxt: Any) -> None:
        self.cam, self.next = CameraStage(width, height, kind), nxt
        self.t0 = time.monotonic()

    def ready(self) -> bool:
        return True

    def run(self, window_s: float, fps: float = FPS) -> int:
        """Produce frames at ``fps`` for ``window_s`` seconds; returns how many were sent."""
        pacer, start, n = Pacer(fps), time.monotonic(), 0
        while time.monotonic() - start < window_s:
            tick = pacer.wait()
            t_start = time.monotonic()
            frame, meta = self.cam.capture((0.0, 0.0, HOVER_M), 0.0, t_start - self.t0)
            ready = time.monotonic()
            self.next.process.remote(ray.put((frame, meta, {"tick": tick, "start": t_start, "ready": ready,
                                                            "out": ready})))
            n += 1
        return n


class DetectorActor:
    def __init__(self, kind: str, stub_ms: float, nxt: Any) -> None:
        self.det, self.next = DetectStage(kind, stub_ms), nxt

    def ready(self) -> bool:
        return True

    def process(self, payload: tuple) -> None:
        t_in = time.monotonic()
        frame, meta, tr = payload
        tr["hop_camera_detector"] = t_in - tr["out"]
        dets, tr["inference_ms"], tr["post_ms"] = self.det(frame, meta)
        tr["out"] = time.monotonic()
        self.next.process.remote(ray.put((dets, meta, tr)))


class FollowActor:
    def __init__(self, nxt: Any) -> None:
        self.follow, self.next = FollowStage(), nxt

    def ready(self) -> bool:
        return True

    def process(self, payload: tuple) -> None:
        t_in = time.monotonic()
        dets, meta, tr = payload
        tr["hop_detector_follow"] = t_in - tr["out"]
        nav, ms = self.follow(dets, meta)
        if nav is None:
            return
        tr["post_ms"] += ms
        tr["out"] = time.monotonic()
        self.next.process.remote(ray.put((nav, meta, tr)))


class SchedulerActor:
    def __init__(self, width: int, height: int, kind: str, nxt: Any) -> None:
        self.cmd, self.next = CommandStage(parsed_config(width, height, kind).robots[0]), nxt

    def ready(self) -> bool:
        return True

    def process(self, payload: tuple) -> None:
        t_in = time.monotonic()
        nav, meta, tr = payload
        tr["hop_follow_scheduler"] = t_in - tr["out"]
        item = self.cmd(nav, tuple(meta.pose.position), meta.capture_time)
        if item is None:
            return
        tr["out"] = time.monotonic()
        self.next.apply.remote(ray.put((item, tr)))


class DroneActor:
    def __init__(self, width: int, height: int, kind: str) -> None:
        self.drone = DroneStage(parsed_config(width, height, kind).robots[0])
        self.rows: list[dict] = []
        self.last = time.monotonic()

    def ready(self) -> bool:
        return True

    def apply(self, payload: tuple) -> None:
        t_in = time.monotonic()
        item, tr = payload
        tr["hop_scheduler_drone"] = t_in - tr["out"]
        self.drone.step(min(0.1, t_in - self.last))
        self.last = t_in
        self.drone.apply(item)
        tr["applied"] = time.monotonic()
        del tr["out"]
        self.rows.append(tr)

    def take(self) -> list[dict]:
        rows, self.rows = self.rows, []
        return rows


class NaiveRayPipeline:
    """Five actors in the current Ray (``ray.init`` must have run). :meth:`window` runs the camera for a while and
    returns the rows of the frames whose command reached the drone actor (see :mod:`aerodaas.bench.pipeline`)."""

    name = "naive_ray"

    def __init__(self, width: int, height: int, kind: str, stub_ms: float) -> None:
        opts = {"num_cpus": 0}
        self.drone = ray.remote(**opts)(DroneActor).remote(width, height, kind)
        sched = ray.remote(**opts)(SchedulerActor).remote(width, height, kind, self.drone)
        follow = ray.remote(**opts)(FollowActor).remote(sched)
        det = ray.remote(**opts)(DetectorActor).remote(kind, stub_ms, follow)
        self.cam = ray.remote(**opts)(CameraActor).remote(width, height, kind, det)
        self.actors = [self.cam, det, follow, sched, self.drone]
        ray.get([a.ready.remote() for a in self.actors], timeout=300)

    def window(self, seconds: float, settle_s: float = 0.5) -> list[dict]:
        ray.get(self.cam.run.remote(seconds))
        time.sleep(settle_s)  # frames still in flight land
        return ray.get(self.drone.take.remote())

    def close(self) -> None:
        for a in self.actors:
            ray.kill(a)
