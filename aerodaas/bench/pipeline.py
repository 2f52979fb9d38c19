"""The work of ``aerodaas bench overhead``'s pipeline as plain stages, so the bare loop and the peer pipelines
(naive Ray, dora-rs) do exactly the same work on the same frames as the AeroDaaS runtime:

camera (render the procedural field or the real imagery at the drone's pose) -> detector (fixed-cost stub or
YOLOX-Nano) -> follow analytics -> trajectory scheduler behind the safety gate -> drone (velocity setpoint applied
to the simulated vehicle backend).

Per frame every pipeline produces one *row* with ``time.monotonic()`` stamps (CLOCK_MONOTONIC, one clock for
every process on the machine, so stamps taken in different processes subtract): ``tick`` (the frame was due),
``ready`` (its pixels exist), ``applied`` (the command reached the backend), and the stage's own work
``inference_ms`` and ``post_ms``. :func:`overheads` turns rows into the two overhead definitions.
"""
from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from aerodaas.analytics.core import Analytics, FollowAnalytics, ObjectDetector
from aerodaas.backends.sim import SimBackend
from aerodaas.config import parse_environment_config
from aerodaas.model.types import AeroNavigation, CameraIntrinsics, Detection, FrameMeta, FramePose
from aerodaas.navigation.safety import SafetyGate
from aerodaas.schedulers import TrajectoryScheduler
from aerodaas.sim.world import World

FPS = 30.0
HOVER_M = 14.0  # metres above the target


class FixedCostDetector(Analytics):
    """A stand-in detector with a fixed inference cost: sleeps ``cost_ms`` (releasing the CPU, like an inference
    accelerator) and reports one ``car`` box of ``box_frac`` of the image at its centre. Input (H, W, 3) uint8
    BGR; output a list with one :class:`Detection`. ``last_timing["inference_ms"]`` is the measured sleep."""

    name = "detector"

    def __init__(self, cost_ms: float = 10.0, box_frac: float = 0.1) -> None:
        super().__init__()
        if cost_ms < 0:
            raise ValueError(f"cost_ms must be >= 0, got {cost_ms}")
        self.cost_ms, self.box_frac = cost_ms, box_frac
        self.last_timing: dict[str, float] = {}

    def process(self, frame: np.ndarray, meta: Any) -> list[Detection]:
        t0 = time.perf_counter()
        time.sleep(self.cost_ms / 1e3)
        self.last_timing = {"inference_ms": (time.perf_counter() - t0) * 1e3}
        h, w = frame.shape[:2]
        bw, bh = w * self.box_frac, h * self.box_frac
        return [Detection(class_id=2, class_name="car", score=0.9,
                          box=(w / 2 - bw / 2, h / 2 - bh / 2, w / 2 + bw / 2, h / 2 + bh / 2))]


def env_config(width: int, height: int, real: bool) -> dict:
    """One drone hovering 14 m above a car (real imagery; YOLOX-Nano finds it there) or a procedural field (stub)."""
    robot = {"id": "uav", "backend": "sim", "takeoff_altitude": HOVER_M, "idle_land_s": 3600,
             "limits": {"max_speed": 3.0, "max_vertical_speed": 4.0, "max_acceleration": 4.0},
             "safety": {"on_violation": "clamp", "max_altitude": 40},
             "sensors": [{"id": "cam", "type": "camera", "properties": {"width": width, "height": height,
                                                                          "hfov_deg": 78, "fps": 30, "pitch_deg": 90}}]}
    world: dict[str, Any] = {"ground": {"seed": 1, "metres_per_pixel": 0.05, "size_m": 120}}
    if real:
        world = {"ground": {"image": "imagery/brighton_beach/DJI_0025.JPG", "metres_per_pixel": 0.02},
                 "targets": [{"id": "car", "class_name": "car", "image": "imagery/brighton_beach/DJI_0033.JPG",
                              "crop": [2960, 420, 3230, 600], "length_m": 5.05,
                              "path": [{"t": 0, "x": 0.0, "y": 0.0}, {"t": 100000, "x": 0.0, "y": 0.0}]}]}
    return {"name": "overhead", "robots": [robot], "world": world,
            "simulation": {"speedup": 1.0, "lockstep": False, "physics_hz": 50}}


def parsed_config(width: int, height: int, kind: str):
    return parse_environment_config(env_config(width, height, kind == "yolox"),
                                    base_dir=os.environ.get("AERODAAS_DATA_DIR"))


def make_detector(kind: str, stub_ms: float) -> Analytics:
    """``stub``: :class:`FixedCostDetector` (``stub_ms``); ``yolox``: YOLOX-Nano on cars, trucks and buses."""
    if kind == "stub":
        return FixedCostDetector(stub_ms)
    return ObjectDetector("yolox_nano", classes=["car", "truck", "bus"], score_threshold=0.15)


class Pacer:
    """A camera's clock at ``fps``: :meth:`wait` sleeps until the next frame is due and returns when it was due
    (``time.monotonic()`` seconds); a frame that would start late is skipped, as a camera would."""

    def __init__(self, fps: float = FPS) -> None:
        self.period = 1.0 / fps
        self.next_t = time.monotonic()

    def restart(self) -> None:
        self.next_t = time.monotonic()

    def wait(self) -> float:
        now = time.monotonic()
        if now < self.next_t:
            time.sleep(self.next_t - now)
        tick, self.next_t = self.next_t, self.next_t + self.period
        if time.monotonic() > self.next_t:  # already late for the next frame: skip ahead
            self.next_t = time.monotonic() + self.period
        return tick


class CameraStage:
    """Renders one (H, W, 3) uint8 read-only frame at a pose (metres ENU, yaw degrees) and builds its FrameMeta."""

    def __init__(self, width: int, height: int, kind: str) -> None:
        cfg = parsed_config(width, height, kind)
        self.world = World(cfg.world.ground, cfg.world.targets)
        self.k = CameraIntrinsics.from_hfov(width, height, 78)
        self.seq = 0

    def capture(self, position: tuple, yaw: float, t: float) -> tuple[np.ndarray, Any]:
        self.seq += 1
        pose = FramePose(position=tuple(float(c) for c in position), yaw=float(yaw), camera_pitch=90)
        frame, _ = self.world.render(pose, self.k, t)
        frame.flags.writeable = False
        meta = FrameMeta(robot_id="uav", sensor_id="cam", seq=self.seq, capture_time=t, wall_time=time.time(),
                         pose=pose, intrinsics=self.k)
        return frame, meta


class DetectStage:
    """The detector; returns ``(detections, inference_ms, post_ms)`` (post = its work outside inference)."""

    def __init__(self, kind: str, stub_ms: float) -> None:
        self.det = make_detector(kind, stub_ms)
        self.det.setup()

    def __call__(self, frame: np.ndarray, meta: Any) -> tuple[list, float, float]:
        t0 = time.perf_counter()
        dets = self.det.process(frame, meta)
        d_ms = (time.perf_counter() - t0) * 1e3
        inf = self.det.last_timing["inference_ms"]
        return dets, inf, d_ms - inf


class FollowStage:
    """The follow analytics; returns ``(AeroNavigation or None, ms spent)`` (the ms count as post-processing)."""

    def __init__(self) -> None:
        self.follow = FollowAnalytics(target_classes=["car", "truck", "bus"], confirm_hits=1, lost_after=1e9)
        self.follow.setup()

    def __call__(self, dets: list, meta: Any) -> tuple[Any, float]:
        t0 = time.perf_counter()
        nav = self.follow.process(dets, meta)
        return (nav if isinstance(nav, AeroNavigation) else None), (time.perf_counter() - t0) * 1e3


class CommandStage:
    """Safety gate + trajectory scheduler: takes the navigation at the drone's position (metres), returns the
    safety-checked item to fly now (or None)."""

    def __init__(self, rc: Any) -> None:
        self.gate = SafetyGate(rc.safety, rc.limits, rc.home)
        self.sched = TrajectoryScheduler()

    def __call__(self, nav: Any, position: tuple, t: float) -> Any:
        nav = self.gate.check_navigation(nav, position)
        self.sched.add_navigation(nav, priority=1, position=position)
        cur = self.sched.current(t)
        return None if cur is None else self.gate.check_item(cur[1], position)


class DroneStage:
    """The simulated vehicle, airborne and holding at the hover altitude; :meth:`apply` sets the velocity."""

    def __init__(self, rc: Any) -> None:
        self.backend = SimBackend(rc)
        self.backend.vehicle.state.position[:] = (0.0, 0.0, rc.takeoff_altitude)
        self.backend.vehicle.state.in_air = self.backend.vehicle.state.armed = True
        self.backend.guidance.hold()

    @property
    def position(self) -> tuple:
        return tuple(float(c) for c in self.backend.state().position)

    def step(self, dt: float) -> None:
        self.backend.step(dt)

    def apply(self, item: Any) -> None:
        self.backend.guidance.set_velocity((item.vx, item.vy, item.vz), item.yaw_rate)


def summary(values: list[float]) -> dict[str, float]:
    a = np.asarray(values, float)
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "mean": float(a.mean()),
            "n": int(a.size)} if a.size else {"median": None, "p99": None, "mean": None, "n": 0}


def mp(s: dict | None) -> dict | None:
    """Just ``{"median", "p99"}`` of a :func:`summary`."""
    return None if s is None else {"median": s.get("median"), "p99": s.get("p99")}


def overheads(rows: list[dict], kind: str, stub_ms: float) -> dict:
    """Summaries of a pipeline's rows: ``framework_overhead_ms`` (paper §8.3.1: ready -> applied − inference −
    post-processing), ``honest_overhead_ms`` (stub only: ready -> applied plus the capture dispatch tick ->
    render start, minus the stub's nominal ``stub_ms``: the render is the camera's work, but dispatch, the
    stub's sleep overshoot, post-processing and every stall count), ``e2e_ms``, ``capture_dispatch_ms``,
    ``inference_ms``."""
    e2e = [(r["applied"] - r["ready"]) * 1e3 for r in rows]
    out = {"commands_applied": len(rows), "e2e_ms": summary(e2e),
           "inference_ms": summary([r["inference_ms"] for r in rows]),
           "post_ms": summary([r["post_ms"] for r in rows]),
           "capture_dispatch_ms": summary([(r["start"] - r["tick"]) * 1e3 for r in rows]),
           "framework_overhead_ms": summary([max(0.0, e - r["inference_ms"] - r["post_ms"])
                                             for e, r in zip(e2e, rows)]),
           "honest_overhead_ms": summary([(r["applied"] - r["ready"] + r["start"] - r["tick"]) * 1e3 - stub_ms
                                           for r in rows])
           if kind == "stub" else None}
    hops = [k for k in rows[0] if k.startswith("hop_")] if rows else []
    for k in hops:
        out.setdefault("hops_ms", {})[k[4:]] = summary([r[k] * 1e3 for r in rows])
    return out
