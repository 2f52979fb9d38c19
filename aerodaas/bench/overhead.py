"""``aerodaas bench overhead``: per-frame framework overhead of the analytics-driven control path.

The path: camera -> detector analytics -> follow analytics -> trajectory scheduler -> drone command (the velocity
setpoint reaching the vehicle backend), at 30 FPS, for each resolution, with the detector replaced by a
fixed-cost stub (``--stub-ms``; it sleeps like an accelerator that releases the CPU, and reports one box) and with
the real YOLOX-Nano (needs the model and the imagery, from ``$AERODAAS_MODEL_DIR``/``$AERODAAS_DATA_DIR``).

Framework overhead = end-to-end latency − inference − post-processing (the AeroDaaS paper's definition, §8.3.1),
per frame whose command reached the drone; end-to-end runs from the moment the frame is ready (rendered) to the
moment the command was applied. It is measured side by side with a *bare loop*: one process, plain function
calls, doing the same work (render, FrameMeta, detector, follow, safety check, scheduler queue, setpoint) at the
same frame rate — the floor. Reported: median and p99 of both, and their ratio.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

import numpy as np

from aerodaas.analytics import Analytics
from aerodaas.models import Detection, FrameMeta

RESOLUTIONS = ((1280, 720), (640, 480))


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


def _env_config(width: int, height: int, real: bool) -> dict:
    """One drone hovering 14 m above a car (real imagery; YOLOX-Nano finds it there) or a procedural field (stub)."""
    robot = {"id": "uav", "backend": "sim", "takeoff_altitude": 14.0, "idle_land_s": 3600,
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


def _detector(kind: str, stub_ms: float):
    from aerodaas.analytics import ObjectDetector

    if kind == "stub":
        return FixedCostDetector(stub_ms)
    return ObjectDetector("yolox_nano", classes=["car", "truck", "bus"], score_threshold=0.15)


def _summary(values: list[float]) -> dict[str, float]:
    a = np.asarray(values, float)
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "mean": float(a.mean()),
            "n": int(a.size)} if a.size else {"median": float("nan"), "p99": float("nan"), "mean": float("nan"), "n": 0}


def framework_run(width: int, height: int, kind: str, duration_s: float, stub_ms: float) -> dict:
    """The real runtime (Ray, the edge host) for ``duration_s`` seconds of flight after take-off."""
    from aerodaas import Environment, FollowAnalytics, PriorityQueue, runtime
    from aerodaas.config import parse_environment_config

    env = Environment(parse_environment_config(_env_config(width, height, kind == "yolox"),
                                               base_dir=os.environ.get("AERODAAS_DATA_DIR")))
    drone = env.get_robot_by_id("uav")
    edge = env.get_compute_resource_by_id("edge")
    from aerodaas.schedulers import TrajectoryScheduler

    sched = TrajectoryScheduler(env)
    det = _detector(kind, stub_ms)
    det.deploy(edge)
    follow = FollowAnalytics(target_classes=["car", "truck", "bus"], confirm_hits=1, lost_after=1e9)
    follow.deploy(edge)
    sched.add_navigation(PriorityQueue(follow.analyse(det.analyse(drone.get_sensor_by_id("cam").get_data_stream())),
                                       priority=1))
    runtime.OPTIONS.progress = False
    takeoff_s = 14.0 / 4.0 + 4.0
    res = drone.start_mission(timeout=duration_s + takeoff_s)
    recs = [r for r in res.stats["uav"]["scheduler"].get("latency_records", []) if r["applied"]]
    cam = res.stats["uav"]["cameras"]["cam"]
    a = res.stats["uav"]["analytics"][0]
    return {"frames_captured": cam.get("frames", 0), "frames_dropped_busy_detector": a.get("dropped", 0),
            "commands_applied": len(recs), "host_errors": res.stats["_hosts"]["edge"].get("error_count", 0),
            "e2e_ms": _summary([r["e2e_ms"] for r in recs]),
            "inference_ms": _summary([r["inference_ms"] for r in recs]),
            "post_ms": _summary([r["post_ms"] for r in recs]),
            "framework_overhead_ms": _summary([r["overhead_ms"] for r in recs]),
            # not in the overhead: from the camera's clock tick to the render starting on the host's thread pool
            # (the bare loop renders in its own loop, with no such hand-off)
            "capture_dispatch_ms": {"median": cam.get("dispatch_ms_median"), "p99": cam.get("dispatch_ms_p99")}}


def bare_loop(width: int, height: int, kind: str, duration_s: float, stub_ms: float) -> dict:
    """The same work in one process with plain function calls, paced at 30 FPS (frames that would start late
    are skipped, as a camera would)."""
    from aerodaas import FollowAnalytics
    from aerodaas.backends.sim import SimBackend
    from aerodaas.config import RobotConfig, WorldConfig, parse_environment_config
    from aerodaas.models import AeroNavigation, CameraIntrinsics, FramePose
    from aerodaas.safety import SafetyGate
    from aerodaas.schedulers import TrajectoryScheduler
    from aerodaas.sim.world import World

    cfg = parse_environment_config(_env_config(width, height, kind == "yolox"),
                                   base_dir=os.environ.get("AERODAAS_DATA_DIR"))
    rc: RobotConfig = cfg.robots[0]
    w: WorldConfig = cfg.world
    world = World(w.ground, w.targets)
    k = CameraIntrinsics.from_hfov(width, height, 78)
    backend = SimBackend(rc)
    backend.vehicle.state.position[:] = (0.0, 0.0, rc.takeoff_altitude)
    backend.vehicle.state.in_air = backend.vehicle.state.armed = True
    backend.hold()
    gate = SafetyGate(rc.safety, rc.limits, rc.home)
    sched = TrajectoryScheduler()
    det = _detector(kind, stub_ms)
    det.setup()
    follow = FollowAnalytics(target_classes=["car", "truck", "bus"], confirm_hits=1, lost_after=1e9)
    follow.setup()
    period = 1.0 / 30.0
    rows = []
    t_start = time.monotonic()
    next_t = t_start
    seq = 0
    while time.monotonic() - t_start < duration_s:
        now = time.monotonic()
        if now < next_t:
            time.sleep(next_t - now)
        next_t += period
        if time.monotonic() > next_t:  # already late for the next frame: skip ahead like a camera
            next_t = time.monotonic() + period
        seq += 1
        t = time.monotonic() - t_start
        backend.step(period)
        pose = FramePose(position=tuple(float(c) for c in backend.position), yaw=float(backend.yaw), camera_pitch=90)
        frame, _ = world.render(pose, k, t)
        frame.flags.writeable = False
        wall = time.time()
        meta = FrameMeta(robot_id="uav", sensor_id="cam", seq=seq, capture_time=t, wall_time=wall, pose=pose,
                         intrinsics=k)
        t0 = time.perf_counter()
        dets = det.process(frame, meta)
        d_ms = (time.perf_counter() - t0) * 1e3
        inf = det.last_timing["inference_ms"]
        t0 = time.perf_counter()
        nav = follow.process(dets, meta)
        f_ms = (time.perf_counter() - t0) * 1e3
        if not isinstance(nav, AeroNavigation):
            continue
        nav = gate.check_navigation(nav, tuple(backend.position))
        sched.add_navigation(nav, priority=1, position=tuple(backend.position))
        cur = sched.current(t)
        if cur is not None:
            item = gate.check_item(cur[1], tuple(backend.position))
            backend.set_velocity((item.vx, item.vy, item.vz), item.yaw_rate)
        e2e = (time.time() - wall) * 1e3
        post = (d_ms - inf) + f_ms
        rows.append({"e2e_ms": e2e, "inference_ms": inf, "post_ms": post, "overhead_ms": max(0.0, e2e - inf - post)})
    return {"commands_applied": len(rows), "e2e_ms": _summary([r["e2e_ms"] for r in rows]),
            "inference_ms": _summary([r["inference_ms"] for r in rows]),
            "framework_overhead_ms": _summary([r["overhead_ms"] for r in rows])}


def run_overhead(duration_s: float = 20.0, stub_ms: float = 10.0, kinds: tuple[str, ...] = ("stub", "yolox"),
                 resolutions: tuple[tuple[int, int], ...] = RESOLUTIONS) -> dict:
    from aerodaas import runtime

    from . import machine_info

    results = []
    for kind in kinds:
        for wdt, hgt in resolutions:
            bare = bare_loop(wdt, hgt, kind, duration_s, stub_ms)
            fw = framework_run(wdt, hgt, kind, duration_s, stub_ms)
            runtime.shutdown_ray()
            fo, bo = fw["framework_overhead_ms"], bare["framework_overhead_ms"]
            row = {"resolution": f"{wdt}x{hgt}", "detector": kind, "fps": 30,
                   "framework_overhead_ms": {"median": fo["median"], "p99": fo["p99"]},
                   "bare_loop_overhead_ms": {"median": bo["median"], "p99": bo["p99"]},
                   "ratio_median": fo["median"] / bo["median"] if bo["median"] > 0 else None,
                   "framework": fw, "bare_loop": bare}
            print(f"overhead {kind:5s} {wdt}x{hgt}: framework median {fo['median']:.3f} ms p99 {fo['p99']:.3f} ms | "
                  f"bare median {bo['median']:.3f} ms p99 {bo['p99']:.3f} ms | ratio {row['ratio_median'] or 0:.1f}x "
                  f"({fw['commands_applied']} / {bare['commands_applied']} commands)", file=sys.stderr, flush=True)
            results.append(row)
    return {"benchmark": "overhead", "machine": machine_info(), "duration_s": duration_s, "stub_ms": stub_ms,
            "definition": "framework overhead = end-to-end (frame ready -> command applied to the vehicle backend) "
                          "- inference - post-processing, per frame whose command reached the drone",
            "targets": {"median_ms": 1.0, "p99_ms": 5.0, "ratio_median": 10.0}, "results": results}


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("overhead", help="per-frame framework overhead (camera -> detector -> follow -> scheduler -> "
                                        "drone) vs a bare single-process loop")
    p.add_argument("--duration", type=float, default=20.0, help="seconds per configuration (after take-off)")
    p.add_argument("--stub-ms", type=float, default=10.0, help="inference time of the fixed-cost stub detector, ms")
    p.add_argument("--detector", choices=["stub", "yolox", "both"], default="both")
    p.add_argument("--resolution", action="append", help="WxH (repeatable; default 1280x720 and 640x480)")
    p.add_argument("--json", action="store_true", help="print the JSON report")
    p.add_argument("--out", help="also write the JSON report to this file")

    def run(a: argparse.Namespace) -> int:
        try:
            res = tuple(tuple(int(v) for v in r.lower().split("x")) for r in a.resolution) if a.resolution else RESOLUTIONS
            if any(len(r) != 2 or min(r) <= 0 for r in res):
                raise ValueError
        except ValueError:
            print(f"aerodaas bench overhead: --resolution expects WxH with positive integers, got {a.resolution}",
                  file=sys.stderr)
            return 2
        kinds = ("stub", "yolox") if a.detector == "both" else (a.detector,)
        if "yolox" in kinds:
            from aerodaas.detect import ModelNotFoundError, resolve_model

            try:
                resolve_model("yolox_nano")
                if not os.environ.get("AERODAAS_DATA_DIR"):
                    raise ModelNotFoundError("AERODAAS_DATA_DIR is not set (the YOLOX run flies over real imagery)")
            except (ModelNotFoundError, OSError) as e:
                print(f"aerodaas bench overhead: the YOLOX-Nano configuration needs the model and imagery: {e}",
                      file=sys.stderr)
                return 2
        report = run_overhead(a.duration, a.stub_ms, kinds, res)
        text = json.dumps(report, indent=2)
        if a.out:
            with open(a.out, "w") as f:
                f.write(text)
        if a.json:
            print(text)
        return 0

    p.set_defaults(func=run)
