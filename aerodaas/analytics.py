"""Analytics (the paper's IAnalyse / INavigableAnalyse) and the built-in ones: an ONNX object detector, a PID
"follow" navigable analytics, and odometry monitoring.

An analytics is a plain Python object built in the application; ``deploy(compute)`` picks its tier and
``analyse(stream)`` wires it into the dataflow. At ``start_mission()`` the runtime ships it to a Ray
actor on that tier, calls :meth:`Analytics.setup` there once (load models), then :meth:`Analytics.process`
for every delivered item. Subclass and override ``setup``/``process`` to write your own.
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np

from .data import AeroStreamData
from .models import AeroNavigation, Detection, FrameMeta, NavigationType, SchedulingType, VelocityCommand

__all__ = ["Analytics", "IAnalyse", "INavigableAnalyse", "NavigableAnalytics", "ObjectDetector",
           "FollowAnalytics", "MonitoringAnalytics"]


class Analytics:
    """Base class (IAnalyse). Subclasses override :meth:`process` and optionally :meth:`setup`.

    ``on_error`` says what an exception raised by :meth:`process` does: ``"continue"`` (default: the item is
    skipped; the error is logged with its traceback, recorded as an ``analytics_error`` event and counted in the
    run's summary) or ``"abort"`` (the same, then every mission of the run ends as ``failed``). Set it on the
    instance (``detector.on_error = "abort"``) or the class; anything else is refused before Ray starts."""

    name: str = "analytics"
    on_error: str = "continue"

    def __init__(self, name: str | None = None) -> None:
        if name:
            self.name = name
        self.compute = None
        self.colocate = False
        self.replicas = 1
        self.inputs: list[AeroStreamData] = []
        self.output = AeroStreamData(source=self)
        self.triggers: list[Analytics] = []
        self.instantiated = False

    def __getstate__(self) -> dict:
        # ship only the analytics itself to its actor, not the build-time dataflow graph around it
        d = self.__dict__.copy()
        for k in ("inputs", "output", "triggers", "compute"):
            d[k] = None
        return d

    # -- IAnalyse
    def deploy(self, compute: Any, *, colocate: bool = False, replicas: int = 1) -> "Analytics":
        """Assign the compute resource (ICompute) this analytics runs on: its actor is placed on a Ray node of the
        resource's tier carrying its labels.

        ``replicas``: run ``n`` actors of this analytics; each drone's items always go to the same replica
        (``index of the drone % n``), so per-drone state (tracks, integrators) stays in one place.
        ``colocate=True``: no actor of its own; a copy runs inside the actor of each drone that feeds it (zero
        actor hops, the drone's own process and GIL: for cheap per-drone analytics such as a follow controller);
        ``compute`` then only names where the drones fly from. Raises ValueError for ``replicas`` < 1 or
        ``replicas`` > 1 with ``colocate``."""
        if not isinstance(replicas, int) or isinstance(replicas, bool) or replicas < 1:
            raise ValueError(f"analytics {self.name!r}: replicas must be an integer >= 1, got {replicas!r}")
        if colocate and replicas != 1:
            raise ValueError(f"analytics {self.name!r}: replicas={replicas} with colocate=True (a colocated "
                             f"analytics runs once inside each drone's actor)")
        self.compute = compute
        self.colocate = bool(colocate)
        self.replicas = replicas
        return self

    def analyse(self, stream: AeroStreamData) -> AeroStreamData:
        """Consume ``stream``; returns this analytics' output stream (AeroStreamData)."""
        if not isinstance(stream, AeroStreamData):
            raise TypeError(f"{self.name}.analyse expects an AeroStreamData, got {type(stream).__name__}")
        self.inputs.append(stream)
        stream.subscribers.append(self)
        return self.output

    def instantiate(self) -> AeroStreamData:
        """Mark this analytics as fed by an external source (no stream input); returns its output stream."""
        self.instantiated = True
        return self.output

    def trigger(self, other: "Analytics") -> "Analytics":
        """Start ``other`` at run time on this analytics' output (it receives every output of this one)."""
        other.analyse(self.output)
        self.triggers.append(other)
        return other

    # -- executed inside the actor
    def setup(self) -> None:
        """Called once on the actor before the first item (load models here)."""

    def process(self, data: Any, meta: FrameMeta | None) -> Any:
        """Process one item; return an output (published downstream) or None."""
        return None


IAnalyse = Analytics


class NavigableAnalytics(Analytics):
    """INavigableAnalyse: ``generate_navigation(data, meta)`` -> AeroNavigation (or None)."""

    def generate_navigation(self, data: Any, meta: FrameMeta | None) -> AeroNavigation | None:
        return None

    def process(self, data: Any, meta: FrameMeta | None) -> AeroNavigation | None:
        return self.generate_navigation(data, meta)


INavigableAnalyse = NavigableAnalytics


class ObjectDetector(Analytics):
    """ONNX object detector on onnxruntime (YOLOX-Nano by default). Input frames (H, W, 3) uint8 BGR; output a
    list of :class:`Detection` (COCO classes, pixel boxes). ``model_path`` may name any compatible ONNX file;
    without it the model is resolved by :func:`aerodaas.detect.resolve_model` (``$AERODAAS_MODEL_DIR``, cache,
    download) where the driver runs, once, and its bytes travel with the analytics to the node that runs it
    (:class:`aerodaas.detect.ShippedModel`: cloud nodes need no copy of their own). ``classes`` restricts to COCO
    names; thresholds are scores in [0, 1]."""

    name = "detector"

    def __init__(self, model: str = "yolox_nano", model_path: str | None = None, classes: Iterable[str] | None = None,
                 score_threshold: float = 0.3, class_thresholds: dict[str, float] | None = None,
                 name: str | None = None, threads: int = 1) -> None:
        super().__init__(name)
        self.model, self.model_path = model, model_path
        self.classes = list(classes) if classes else None
        self.score_threshold = score_threshold
        self.class_thresholds = class_thresholds
        self.threads = threads
        self.detector = None
        self.shipped = None  # the model's bytes, read by check() on the driver
        self.last_timing: dict[str, float] = {}
        self.n_frames = 0
        self.n_with_dets = 0

    def check(self) -> None:
        """Resolve the model now (driver side), so a missing model fails before any actor starts."""
        from .detect import ShippedModel, resolve_model

        self.model_path = str(resolve_model(self.model, self.model_path))  # the actor loads exactly these bytes
        self.shipped = ShippedModel.read(self.model_path)

    def setup(self) -> None:
        from .detect import make_detector

        path = self.shipped.path_on_this_node(self.model_path) if self.shipped is not None else self.model_path
        self.detector = make_detector(self.model, model_path=path, score_threshold=self.score_threshold,
                                      classes=self.classes, class_thresholds=self.class_thresholds,
                                      intra_op_threads=self.threads)

    def process(self, frame: np.ndarray, meta: FrameMeta | None) -> list[Detection]:
        dets = self.detector.detect(frame)
        t = self.detector.last_timing
        self.last_timing = {"inference_ms": t["inference_ms"], "pre_ms": t["preprocess_ms"], "post_ms": t["postprocess_ms"]}
        self.n_frames += 1
        self.n_with_dets += bool(dets)
        return dets

    def stats(self) -> dict:
        return {"frames": self.n_frames, "frames_with_detections": self.n_with_dets}


class FollowAnalytics(NavigableAnalytics):
    """Follow a detected target: turns its pixel box into ENU velocity commands with a PID controller.

    The box centre is back-projected through the frame's camera pose onto the ground plane
    (:func:`aerodaas.sim.world.pixel_to_ground`), giving the target's ground position; a simple gated track
    (nearest detection to the predicted position) keeps it locked. The command is
    ``v = kp·e + ki·∫e dt + kd·de/dt + v_target`` where ``e`` is the horizontal ground error in metres
    (target minus drone), ``kp`` in 1/s, ``ki`` in 1/s², ``kd`` dimensionless, and ``v_target`` the
    target's estimated velocity (feed-forward), clipped to ``max_speed`` m/s. Each command lasts
    ``command_duration`` s. The track must be confirmed by ``confirm_hits`` detections; after ``lost_after``
    seconds without a detection it is dropped and no more commands are issued (the preempted mission resumes).
    ``standoff_m`` > 0 keeps the drone that many metres (horizontally) behind the target along its heading
    (e.g. 2 m for following a person), instead of directly above it.
    """

    name = "follow"

    def __init__(self, target_classes: Iterable[str] = ("car", "truck", "bus"), kp: float = 0.8, ki: float = 0.02,
                 kd: float = 0.1, max_speed: float = 4.0, command_duration: float = 0.5, gate_m: float = 4.0,
                 confirm_hits: int = 2, lost_after: float = 2.0, standoff_m: float = 0.0,
                 name: str | None = None) -> None:
        super().__init__(name)
        self.standoff_m = float(standoff_m)
        self._away = np.array([0.0, -1.0])  # unit vector from the target to the standoff point
        self.target_classes = set(target_classes)
        self.kp, self.ki, self.kd = kp, ki, kd
        self.max_speed, self.command_duration = max_speed, command_duration
        self.gate_m, self.confirm_hits, self.lost_after = gate_m, confirm_hits, lost_after
        self._reset()
        self.commands = 0

    def _reset(self) -> None:
        self.track: np.ndarray | None = None
        self.track_v = np.zeros(2)
        self.track_t = 0.0
        self.hits = 0
        self.integral = np.zeros(2)
        self.prev_err: np.ndarray | None = None
        self.prev_t: float | None = None

    def generate_navigation(self, dets: list[Detection], meta: FrameMeta | None) -> AeroNavigation | None:
        from .sim.world import pixel_to_ground

        if meta is None:
            return None
        t = meta.capture_time
        drone = np.array(meta.pose.position[:2])
        cands = []
        for d in dets:
            if d.class_name not in self.target_classes:
                continue
            g = pixel_to_ground(*d.center, meta.pose, meta.intrinsics)
            if g is not None:
                cands.append((d, np.array(g)))
        pred = None if self.track is None else self.track + self.track_v * (t - self.track_t)
        best = None
        if cands:
            if pred is None:
                best = max(cands, key=lambda c: c[0].score)
            else:
                c = min(cands, key=lambda c: float(np.linalg.norm(c[1] - pred)))
                if np.linalg.norm(c[1] - pred) <= self.gate_m:
                    best = c
        if best is not None:
            p = best[1]
            if self.track is not None and t > self.track_t:
                v_new = (p - self.track) / (t - self.track_t)
                self.track_v = 0.7 * self.track_v + 0.3 * v_new if self.hits > 1 else v_new * 0.0
            self.track, self.track_t = p, t
            self.hits += 1
        elif self.track is None or t - self.track_t > self.lost_after:
            if self.track is not None:
                self._reset()
            return None
        if self.hits < self.confirm_hits:
            return None
        target = self.track + self.track_v * (t - self.track_t)
        if self.standoff_m > 0:  # stay standoff_m behind the target (along its heading), or where we are if it stops
            sp = float(np.hypot(*self.track_v))
            if sp > 0.2:
                self._away = -self.track_v / sp
            elif np.hypot(*(drone - target)) > 0.3:
                self._away = (drone - target) / np.hypot(*(drone - target))
            target = target + self._away * self.standoff_m
        err = target - drone
        dt = (t - self.prev_t) if self.prev_t is not None else 0.0
        if dt > 0:
            self.integral = np.clip(self.integral + err * dt, -5.0, 5.0)
        deriv = (err - self.prev_err) / dt if (self.prev_err is not None and dt > 0) else np.zeros(2)
        self.prev_err, self.prev_t = err, t
        v = self.kp * err + self.ki * self.integral + self.kd * deriv + self.track_v
        n = float(np.hypot(*v))
        if n > self.max_speed:
            v *= self.max_speed / n
        self.commands += 1
        cmd = VelocityCommand(id=f"follow-{meta.seq}", vx=float(v[0]), vy=float(v[1]), vz=0.0,
                              duration=self.command_duration, issued_at=t)
        return AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [cmd], SchedulingType.ORDERED, name="follow")

    def stats(self) -> dict:
        return {"commands": self.commands}


class MonitoringAnalytics(Analytics):
    """Watches odometry fields (any of ``battery``, ``height``, ``gps``, ``speed``) and reports them with running
    minima/maxima; raises warnings when a ``limits`` bound (e.g. ``{"battery": 20}`` percent minimum,
    ``{"height": 30}`` metres maximum) is crossed. Output: a dict per odometry message."""

    name = "monitor"
    FIELDS = ("battery", "height", "gps", "speed")

    def __init__(self, watch: Iterable[str] = ("battery", "height", "gps"), limits: dict[str, float] | None = None,
                 name: str | None = None) -> None:
        super().__init__(name)
        self.watch = list(watch)
        bad = [w for w in self.watch if w not in self.FIELDS + ("camera",)]
        if bad:
            raise ValueError(f"watch: unknown fields {bad}; choose from {list(self.FIELDS)}")
        self.limits = limits or {}
        self.summary: dict[str, dict[str, float]] = {}
        self.warnings: list[str] = []

    def process(self, odom: dict, meta: Any) -> dict:
        vals: dict[str, Any] = {}
        if "battery" in self.watch:
            vals["battery"] = odom["battery_pct"]
        if "height" in self.watch:
            vals["height"] = odom["position"][2]
        if "speed" in self.watch:
            vals["speed"] = math.hypot(*odom["velocity"])
        if "gps" in self.watch:
            vals["gps"] = [odom["geodetic"]["lat"], odom["geodetic"]["lon"], odom["geodetic"]["alt"]]
        for k, v in vals.items():
            if isinstance(v, (int, float)):
                s = self.summary.setdefault(k, {"min": v, "max": v})
                s["min"], s["max"] = min(s["min"], v), max(s["max"], v)
        if "battery" in self.limits and (vals.get("battery") if vals.get("battery") is not None else 100) \
                < self.limits["battery"]:
            self.warnings.append(f"battery {vals['battery']:.1f}% below {self.limits['battery']}% at t={odom['t']:.1f}s")
        if "height" in self.limits and vals.get("height", 0) > self.limits["height"]:
            self.warnings.append(f"height {vals['height']:.1f} m above {self.limits['height']} m at t={odom['t']:.1f}s")
        return {"t": odom["t"], **vals}

    def stats(self) -> dict:
        return {"summary": self.summary, "warnings": self.warnings[-5:]}
