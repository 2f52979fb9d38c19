"""Analytics (the paper's IAnalyse / INavigableAnalyse) and the built-in ones: an ONNX object detector, a PID
"follow" navigable analytics, and odometry monitoring.

An analytics is a plain Python object built in the application; ``deploy(compute)`` picks its tier and
``analyse(stream)`` wires it into the dataflow. At ``start_mission()`` the runtime ships it to a Ray
actor on that tier, calls :meth:`Analytics.setup` there once (load models), then :meth:`Analytics.process`
for every delivered item (or :meth:`Analytics.process_batch` for several at once). Subclass and override
``setup``/``process`` to write your own.

One analytics object may be fed by several drones (one shared detector or follow controller for a fleet). Whatever
it remembers between items must then be kept per drone: :func:`source_robot` names the drone an item comes from
and :meth:`Analytics.drone_state` holds one state object per drone. The built-in analytics keep all their memory
(tracks, PID integrators, confirmation streaks, running minima/maxima) that way.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Sequence, TypeVar

import numpy as np

from aerodaas.model.data import AeroStreamData
from aerodaas.model.types import AeroNavigation, Detection, FrameMeta, NavigationType, SchedulingType, VelocityCommand
from aerodaas.perception.track_records import TrackRecording, track_and_keep

__all__ = ["Analytics", "IAnalyse", "INavigableAnalyse", "NavigableAnalytics", "ObjectDetector",
           "FollowAnalytics", "FollowTrack", "MonitoringAnalytics", "source_robot"]

_S = TypeVar("_S")


def source_robot(data: Any, meta: Any) -> str:
    """The id of the drone (robot) an analytics input item comes from.

    * A camera frame, and everything an analytics derives from one (detections, navigation), travels with the
      frame's :class:`~aerodaas.model.types.FrameMeta`: its ``robot_id``.
    * Odometry (``meta`` None) is an :class:`~aerodaas.model.types.Odometry` dict or model: its ``robot_id``.
    * A stat-stream message (``meta`` None) is a dict with a ``robot`` field.

    Returns ``""`` when the item names no drone (an environment sensor's value): such items share one state."""
    rid = getattr(meta, "robot_id", None)
    if rid:
        return str(rid)
    if isinstance(data, dict):
        rid = data.get("robot_id") or data.get("robot")
    else:
        rid = getattr(data, "robot_id", None)
    return str(rid) if rid else ""


class Analytics:
    """Base class (IAnalyse). Subclasses override :meth:`process` and optionally :meth:`setup`.

    ``on_error`` says what an exception raised by :meth:`process` does: ``"continue"`` (default: the item is
    skipped; the error is logged with its traceback, recorded as an ``analytics_error`` event and counted in the
    run's summary) or ``"abort"`` (the same, then every mission of the run ends as ``failed``). Set it on the
    instance (``detector.on_error = "abort"``) or the class; anything else is refused before Ray starts."""

    name: str = "analytics"
    #: plug-in declaration (aerodaas.plugins.registry; docs/extending.md): its kind; ``consumes``/``produces`` name
    #: the messages it takes and returns (e.g. ``("frame",)`` -> ``(Detection,)``), for ``aerodaas plugins``
    plugin_kind: str = "analytics"
    consumes: tuple = ()
    produces: tuple = ()
    on_error: str = "continue"
    #: Most items the runtime should hand to one :meth:`process_batch` call (1: no batching pays off). Read on the
    #: actor after :meth:`setup`; the ONNX detectors raise it when their model takes a dynamic batch.
    max_batch: int = 1
    #: True when the analytics remembers anything between items of one drone (a track, an integrator, a streak):
    #: a runtime that spreads items over ``replicas`` must then send every item of a drone to the same replica
    #: (route by :func:`source_robot`). False (e.g. :class:`ObjectDetector`): any replica may take any item.
    stateful: bool = True

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

    def process_batch(self, items: Sequence[tuple[Any, FrameMeta | None]]) -> list[Any]:
        """Process several delivered items at once, possibly from different drones (e.g. the latest frame of each
        drone feeding one detector): ``items`` is a sequence of ``(data, meta)`` pairs exactly as :meth:`process`
        takes them; returns one output per item, in the same order (None: no output for that item).

        Default: ``[self.process(data, meta) for data, meta in items]``, so every analytics supports it; an
        analytics whose work vectorises (one DNN inference call for several frames) overrides it and raises
        :attr:`max_batch`. Errors: whatever :meth:`process` raises; when it raises, no output of the batch is
        valid (a runtime re-runs the items one by one with :meth:`process` to attribute the failure, which is safe
        for the analytics that batch: they are not :attr:`stateful`)."""
        return [self.process(data, meta) for data, meta in items]

    # -- per-drone state (one analytics object may serve a fleet)
    def drone_state(self, data: Any, meta: Any, factory: Callable[[], _S]) -> _S:
        """This analytics' state object for the drone the item ``(data, meta)`` comes from
        (:func:`source_robot`), made by ``factory()`` on that drone's first item. Keep in it everything remembered
        between items, so that drones sharing this analytics never mix (issue 15)."""
        states = self.__dict__.setdefault("_drone_states", {})
        key = source_robot(data, meta)
        st = states.get(key)
        if st is None:
            st = states.setdefault(key, factory())
        return st

    def drone_states(self) -> dict[str, Any]:
        """The per-drone state objects made so far, by robot id (``""``: items naming no drone)."""
        return dict(self.__dict__.get("_drone_states", {}))

    def reset_drone(self, robot_id: str) -> None:
        """Forget what this analytics remembers about drone ``robot_id`` (e.g. after that drone's actor restarted
        from a checkpoint); a no-op for a drone it has not seen."""
        self.__dict__.get("_drone_states", {}).pop(robot_id, None)


IAnalyse = Analytics


class NavigableAnalytics(Analytics):
    """INavigableAnalyse: ``generate_navigation(data, meta)`` -> AeroNavigation (or None)."""

    def generate_navigation(self, data: Any, meta: FrameMeta | None) -> AeroNavigation | None:
        return None

    def process(self, data: Any, meta: FrameMeta | None) -> AeroNavigation | None:
        return self.generate_navigation(data, meta)


INavigableAnalyse = NavigableAnalytics


class ObjectDetector(TrackRecording, Analytics):
    """ONNX object detector on onnxruntime (YOLOX-Nano by default). Input frames (H, W, 3) uint8 BGR; output a
    list of :class:`Detection` (COCO classes, pixel boxes). ``model_path`` may name any compatible ONNX file;
    without it the model is resolved by :func:`aerodaas.perception.detect.resolve_model` (``$AERODAAS_MODEL_DIR``, cache,
    download) where the driver runs, once, and its bytes travel with the analytics to the node that runs it
    (:class:`aerodaas.perception.detect.ShippedModel`: cloud nodes need no copy of their own). ``classes`` restricts to the
    model's class names (a plain string is one class; ``[]`` is refused); thresholds are scores in [0, 1].

    Bring your own model (issue 28): ``model_path`` with ``format`` ``"auto"`` (recognised from the graph),
    ``"yolox"``, ``"nanodet"`` or ``"ultralytics"`` (YOLOv5 / YOLOv8 / YOLO11 ONNX exports,
    :mod:`aerodaas.perception.decoders`); ``class_names`` (else the model's metadata ``names``, else COCO for the
    YOLOX/NanoDet formats); ``input_size=(H, W)`` for an export with dynamic axes. ``nms_threshold`` (IoU),
    ``agnostic_nms`` (one NMS over all classes) and ``class_groups`` (``{"vehicle": ["car", "truck", "bus"]}``:
    class-agnostic NMS within a group); ``class_thresholds`` per class. ``tiling``: a
    :class:`aerodaas.perception.tiling.Tiling` for small objects in large frames. All options are checked by
    :meth:`check` in the pre-flight, before Ray starts; :meth:`process` before :meth:`setup` raises RuntimeError.

    Several drones may share one detector: it remembers nothing between frames (not :attr:`stateful`), and
    :meth:`process_batch` runs the frames of several drones in one onnxruntime call, up to ``batch`` frames, when
    the model's input has a dynamic batch dimension (:attr:`max_batch` is then ``batch``). The shipped YOLOX-Nano
    and NanoDet-Plus exports have a fixed batch of 1: with them :attr:`max_batch` is 1 and :meth:`process_batch`
    is a loop over :meth:`process`. Raises ValueError for ``batch`` < 1.

    ``tracker``: a :class:`aerodaas.perception.tracking.ByteTrackConfig` also runs ByteTrack per drone on the
    detections (the output stays the detections); each drone's geo-located tracks are recorded in a run under
    ``/{robot}/{name}/tracks`` (:mod:`aerodaas.perception.track_records`). The detector is then :attr:`stateful`."""

    name = "detector"
    stateful = False
    consumes, produces = ("frame",), ("detections",)

    def __init__(self, model: str = "yolox_nano", model_path: str | None = None,
                 classes: Iterable[str] | str | None = None, score_threshold: float = 0.3,
                 class_thresholds: dict[str, float] | None = None,
                 name: str | None = None, threads: int = 1, batch: int = 8, *, format: str = "auto",
                 nms_threshold: float = 0.45, agnostic_nms: bool = False,
                 class_groups: dict[str, Iterable[str]] | None = None, input_size: tuple[int, int] | None = None,
                 class_names: Sequence[str] | None = None, tiling: Any = None, tracker: Any = None) -> None:
        from aerodaas.perception.options import normalise_classes

        super().__init__(name)
        if not (isinstance(batch, int) and batch >= 1):
            raise ValueError(f"ObjectDetector batch must be an integer >= 1 (frames per inference call), got {batch!r}")
        self.batch = batch
        self.model, self.model_path = model, model_path
        self.classes = normalise_classes(classes)  # "car" is one class; [] is refused
        self.score_threshold = score_threshold
        self.class_thresholds = class_thresholds
        self.threads = threads
        self.format = format
        self.nms_threshold = nms_threshold
        self.agnostic_nms = agnostic_nms
        self.class_groups = {g: normalise_classes(m, f"class_groups[{g!r}]") for g, m in (class_groups or {}).items()}
        self.input_size = tuple(input_size) if input_size is not None else None
        self.class_names = list(class_names) if class_names is not None else None
        self.tiling = tiling
        if tiling is not None:  # a bad slice size fails where the app wrote it (ValueError naming the field)
            tiling.check()
        self.tracker = tracker
        if tracker is not None:
            tracker.check()
            self.stateful = True  # one ByteTracker per drone: each drone's frames must reach the same replica
        self.detector = None
        self.shipped = None  # the model's bytes, read by check() on the driver
        self.last_timing: dict[str, float] = {}
        self.n_frames = 0
        self.n_with_dets = 0
        self.n_batched = 0

    def check(self) -> None:
        """Driver side, before any actor starts (called by the pre-flight): check every option
        (:func:`aerodaas.perception.options.check_detector_options`: thresholds, class names against the model's,
        class groups, input size, the model's format) and resolve the model, so a typo or a missing model fails
        with a ValueError naming the field and the value (``aerodaas run`` exits 2)."""
        from aerodaas.perception.detect import ShippedModel, resolve_model
        from aerodaas.perception.options import check_detector_options

        if self.tiling is not None:
            self.tiling.check()
        if self.tracker is not None:
            self.tracker.check()
        self.model_path = str(resolve_model(self.model, self.model_path))  # the actor loads exactly these bytes
        check_detector_options(name=self.name, model=self.model, model_path=self.model_path, format=self.format,
                               classes=self.classes, score_threshold=self.score_threshold,
                               nms_threshold=self.nms_threshold, class_thresholds=self.class_thresholds,
                               class_groups=self.class_groups, input_size=self.input_size,
                               class_names=self.class_names)
        self.shipped = ShippedModel.read(self.model_path)

    def setup(self) -> None:
        from aerodaas.perception.options import build_detector

        path = self.shipped.path_on_this_node(self.model_path) if self.shipped is not None else self.model_path
        self.detector = build_detector(self.model, model_path=path, format=self.format,
                                       score_threshold=self.score_threshold, nms_threshold=self.nms_threshold,
                                       classes=self.classes, class_thresholds=self.class_thresholds,
                                       intra_op_threads=self.threads, agnostic_nms=self.agnostic_nms,
                                       class_groups=self.class_groups or None, input_size=self.input_size,
                                       class_names=self.class_names)
        if self.tiling is not None:
            from aerodaas.perception.tiling import TiledDetector

            self.detector = TiledDetector(self.detector, self.tiling)

    def _ready(self):
        if self.detector is None:
            raise RuntimeError(f"analytics {self.name!r}: process() called before setup(); the runtime calls "
                               f"setup() on the actor first (call it yourself when using the detector directly)")
        return self.detector

    @property
    def max_batch(self) -> int:  # type: ignore[override]
        """Frames per :meth:`process_batch` inference call: ``batch`` when the loaded model (after :meth:`setup`)
        takes a dynamic batch, else 1."""
        d = self.detector
        return self.batch if d is not None and getattr(d, "batch_dynamic", False) else 1

    def process(self, frame: np.ndarray, meta: FrameMeta | None) -> list[Detection]:
        dets = self._ready().detect(frame)
        t = self.detector.last_timing
        self.last_timing = {"inference_ms": t["inference_ms"], "pre_ms": t["preprocess_ms"], "post_ms": t["postprocess_ms"]}
        self.n_frames += 1
        self.n_with_dets += bool(dets)
        if self.tracker is not None:
            track_and_keep(self, dets, meta, self.tracker)
        return dets

    def process_batch(self, items: Sequence[tuple[np.ndarray, FrameMeta | None]]) -> list[list[Detection]]:
        """Detections for each ``(frame, meta)`` of ``items`` (frames of any drones), in order, equal to what
        :meth:`process` returns for each; one onnxruntime call per ``max_batch`` frames when the model allows (see
        the class docstring). ``last_timing`` is then per frame (the call's times divided by its frames) with
        ``batch`` = the most frames in one call. Raises ValueError naming the index of a frame that is not (H, W, 3) uint8."""
        if not items:
            return []
        frames = [f for f, _ in items]
        out = self._ready().detect_batch(frames, max_batch=max(self.max_batch, 1))
        t, n = self.detector.last_timing, len(frames)
        self.last_timing = {"inference_ms": t["inference_ms"] / n, "pre_ms": t["preprocess_ms"] / n,
                            "post_ms": t["postprocess_ms"] / n, "batch": float(self.detector.last_batch)}
        self.n_frames += n
        self.n_with_dets += sum(bool(d) for d in out)
        self.n_batched += self.detector.last_batched
        if self.tracker is not None:
            for dets, (_, meta) in zip(out, items):
                track_and_keep(self, dets, meta, self.tracker)
        return out

    def stats(self) -> dict:
        """``frames``, ``frames_with_detections`` and ``frames_batched`` (inferred in a call with other frames)."""
        return {"frames": self.n_frames, "frames_with_detections": self.n_with_dets,
                "frames_batched": getattr(self, "n_batched", 0)}


@dataclass
class FollowTrack:
    """One drone's follow state (:class:`FollowAnalytics` keeps one per drone): the target's ground position
    ``track`` (ENU metres, None: no track) and velocity ``track_v`` (m/s) at sim time ``track_t`` (s), the
    detections ``hits`` that fed it, the PID integral (metre-seconds) and previous error (metres) at ``prev_t``,
    the standoff direction ``away`` (unit ENU vector), the ``commands`` issued to this drone, and the smoothed
    interval ``frame_interval_s`` (s, capture time) between the frames that reached the follow at ``last_frame_t``."""

    track: np.ndarray | None = None
    track_v: np.ndarray = field(default_factory=lambda: np.zeros(2))
    track_t: float = 0.0
    hits: int = 0
    integral: np.ndarray = field(default_factory=lambda: np.zeros(2))
    prev_err: np.ndarray | None = None
    prev_t: float | None = None
    away: np.ndarray = field(default_factory=lambda: np.array([0.0, -1.0]))
    commands: int = 0
    frame_interval_s: float | None = None
    last_frame_t: float | None = None
    tracker: Any = None  # this drone's ByteTracker (FollowAnalytics(tracker=...)), None: gated nearest detection
    target_id: int | None = None  # the track id followed (with a tracker)

    def saw_frame(self, t: float, longest_gap_s: float) -> None:
        """Note a frame captured at sim time ``t`` (s): ``frame_interval_s`` follows the gaps between frames with
        an exponential average (weight 0.3 on the newest gap), each gap cut to ``longest_gap_s`` (a pause, such as
        a detector restarting, is not the detector's pace); a frame older than the newest seen is not a gap."""
        if self.last_frame_t is not None:
            if t <= self.last_frame_t:
                return
            gap = min(t - self.last_frame_t, longest_gap_s)
            self.frame_interval_s = gap if self.frame_interval_s is None else 0.7 * self.frame_interval_s + 0.3 * gap
        self.last_frame_t = t

    def drop(self) -> None:
        """Lose the target: clear the track and the controller memory (``away``, ``commands`` and the frame
        interval stay)."""
        self.track, self.track_v, self.track_t, self.hits = None, np.zeros(2), 0.0, 0
        self.target_id = None
        self.integral, self.prev_err, self.prev_t = np.zeros(2), None, None


class FollowAnalytics(TrackRecording, NavigableAnalytics):
    """Follow a detected target: turns its pixel box into ENU velocity commands with a PID controller.

    The box centre is back-projected through the frame's camera pose onto the ground plane
    (:func:`aerodaas.model.camera.pixel_to_ground`), giving the target's ground position; a simple gated track
    (nearest detection to the predicted position) keeps it locked. The command is
    ``v = kp·e + ki·∫e dt + kd·de/dt + v_target`` where ``e`` is the horizontal ground error in metres
    (target minus drone), ``kp`` in 1/s, ``ki`` in 1/s², ``kd`` dimensionless, and ``v_target`` the
    target's estimated velocity (feed-forward), clipped to ``max_speed`` m/s. Each command lasts
    ``command_duration`` s from its frame's capture time, stretched by twice the interval between the frames
    that reach the follow for this drone (to at most ``lost_after`` and 4 x ``command_duration``): with a
    detector slower than the camera the frames that get analysed arrive late and far apart (80 ms of inference
    on a 2-core machine is 0.32 s of vehicle time at 4x real time), and a command that expired before the next
    one arrived handed the drone back to the preempted mission between every two detections (TRACKING and
    NAVIGATING alternated every 0.1-0.4 s). The track must be confirmed by ``confirm_hits`` detections; after
    ``lost_after`` seconds without a detection it is dropped and no more commands are issued (the preempted
    mission resumes once the last command runs out).
    ``standoff_m`` > 0 keeps the drone that many metres (horizontally) behind the target along its heading
    (e.g. 2 m for following a person), instead of directly above it.

    Shared by several drones, it keeps one :class:`FollowTrack` per drone (keyed by the frame's
    ``FrameMeta.robot_id``): each drone follows what its own camera sees, with its own PID memory.

    ``tracker``: a :class:`aerodaas.perception.tracking.ByteTrackConfig` makes it follow a **track id** (issue 28):
    each drone runs its own ByteTracker on the target-class detections; the followed id is kept while that track
    is seen, whatever other boxes come near, and ByteTrack re-acquires it under the same id after a short occlusion
    (``track_buffer`` frames); when the id is gone for good, the track nearest the predicted ground position within
    ``gate_m`` is adopted. ``None`` (default): the gated nearest detection of each frame, as before. With a tracker
    the drone's tracks are also recorded in a run (:mod:`aerodaas.perception.track_records`, under
    ``/{robot}/{name}/tracks``: image annotations with the track ids, a 3-D scene and a ``LocationFix`` per track).
    """

    name = "follow"
    consumes, produces = ("detections",), ("navigation",)

    def __init__(self, target_classes: Iterable[str] = ("car", "truck", "bus"), kp: float = 0.8, ki: float = 0.02,
                 kd: float = 0.1, max_speed: float = 4.0, command_duration: float = 0.5, gate_m: float = 4.0,
                 confirm_hits: int = 2, lost_after: float = 2.0, standoff_m: float = 0.0,
                 name: str | None = None, tracker: Any = None) -> None:
        super().__init__(name)
        if tracker is not None:
            tracker.check()
        self.tracker = tracker
        self.standoff_m = float(standoff_m)
        self.target_classes = set(target_classes)
        self.kp, self.ki, self.kd = kp, ki, kd
        self.max_speed, self.command_duration = max_speed, command_duration
        self.gate_m, self.confirm_hits, self.lost_after = gate_m, confirm_hits, lost_after


    def track_of(self, robot_id: str) -> FollowTrack | None:
        """The follow state of drone ``robot_id`` (None before its first frame)."""
        return self.drone_states().get(robot_id)

    @property
    def commands(self) -> int:
        """Velocity commands issued, all drones together."""
        return sum(st.commands for st in self.drone_states().values())

    def generate_navigation(self, dets: list[Detection], meta: FrameMeta | None) -> AeroNavigation | None:
        from aerodaas.model.camera import pixel_to_ground

        if meta is None:
            return None
        st = self.drone_state(dets, meta, FollowTrack)
        t = meta.capture_time
        st.saw_frame(t, self._longest_command_s())
        drone = np.array(meta.pose.position[:2])
        cands = []
        ids: list[int | None] = []
        if self.tracker is not None:
            from aerodaas.perception.track_records import track_rows
            from aerodaas.perception.tracking import ByteTracker

            if st.tracker is None:
                st.tracker = ByteTracker(self.tracker)
            active = st.tracker.update([d for d in dets if d.class_name in self.target_classes])
            self.keep_tracks(meta, track_rows(active, meta))  # recorded by the runtime (perception.track_records)
            seen = [(tr.detection, tr.track_id) for tr in active]
        else:
            seen = [(d, None) for d in dets if d.class_name in self.target_classes]
        for d, tid in seen:
            g = pixel_to_ground(*d.center, meta.pose, meta.intrinsics)
            if g is not None:
                cands.append((d, np.array(g)))
                ids.append(tid)
        pred = None if st.track is None else st.track + st.track_v * (t - st.track_t)
        best = None
        coasting = (st.target_id is not None and st.target_id not in ids
                    and any(tr.track_id == st.target_id for tr in st.tracker.tracks))
        if st.target_id is not None and st.target_id in ids:  # the followed track is seen: keep it
            best = cands[ids.index(st.target_id)]
        elif coasting:  # hidden but still alive in ByteTrack (lost, within its buffer): adopt no other object
            best = None
        elif cands:
            if pred is None:
                best = max(cands, key=lambda c: c[0].score)
            else:
                c = min(cands, key=lambda c: float(np.linalg.norm(c[1] - pred)))
                if np.linalg.norm(c[1] - pred) <= self.gate_m:
                    best = c
        if best is not None:
            if self.tracker is not None:
                st.target_id = ids[next(i for i, c in enumerate(cands) if c is best)]
            p = best[1]
            if st.track is not None and t > st.track_t:
                v_new = (p - st.track) / (t - st.track_t)
                st.track_v = 0.7 * st.track_v + 0.3 * v_new if st.hits > 1 else v_new * 0.0
            st.track, st.track_t = p, t
            st.hits += 1
        elif st.track is None or t - st.track_t > self.lost_after:
            if st.track is not None:
                st.drop()
            return None
        if st.hits < self.confirm_hits:
            return None
        target = st.track + st.track_v * (t - st.track_t)
        if self.standoff_m > 0:  # stay standoff_m behind the target (along its heading), or where we are if it stops
            sp = float(np.hypot(*st.track_v))
            if sp > 0.2:
                st.away = -st.track_v / sp
            elif np.hypot(*(drone - target)) > 0.3:
                st.away = (drone - target) / np.hypot(*(drone - target))
            target = target + st.away * self.standoff_m
        err = target - drone
        dt = (t - st.prev_t) if st.prev_t is not None else 0.0
        if dt > 0:
            st.integral = np.clip(st.integral + err * dt, -5.0, 5.0)
        deriv = (err - st.prev_err) / dt if (st.prev_err is not None and dt > 0) else np.zeros(2)
        st.prev_err, st.prev_t = err, t
        v = self.kp * err + self.ki * st.integral + self.kd * deriv + st.track_v
        n = float(np.hypot(*v))
        if n > self.max_speed:
            v *= self.max_speed / n
        st.commands += 1
        cmd = VelocityCommand(id=f"follow-{meta.seq}", vx=float(v[0]), vy=float(v[1]), vz=0.0,
                              duration=self.duration_for(st), issued_at=t)
        return AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [cmd], SchedulingType.ORDERED, name="follow")

    def _longest_command_s(self) -> float:
        """The most a command is stretched to (s): ``lost_after``, and at most 4 x ``command_duration``."""
        return max(self.command_duration, min(self.lost_after, 4.0 * self.command_duration))

    def duration_for(self, st: FollowTrack) -> float:
        """A command's lifetime (s) for the drone whose state is ``st``: ``command_duration`` + twice its frame
        interval (it must outlive the wait for the next analysed frame plus that frame's latency, which is about
        one interval when the detector is the bottleneck), within [``command_duration``, ``lost_after``] and at
        most 4 x ``command_duration``."""
        d = self.command_duration
        if st.frame_interval_s is not None:
            d = min(d + 2.0 * st.frame_interval_s, self._longest_command_s())
        return float(min(d, 3600.0))

    def stats(self) -> dict:
        """``commands`` (all drones) and ``commands_by_drone`` (robot id -> velocity commands issued)."""
        by = {rid: st.commands for rid, st in self.drone_states().items()}
        return {"commands": sum(by.values()), "commands_by_drone": by}


class MonitoringAnalytics(Analytics):
    """Watches odometry fields (any of ``battery``, ``height``, ``gps``, ``speed``) and reports them with running
    minima/maxima; raises warnings when a ``limits`` bound (e.g. ``{"battery": 20}`` percent minimum,
    ``{"height": 30}`` metres maximum) is crossed. Output: a dict per odometry message (``t`` s, ``robot``, the
    watched values). Shared by several drones, it keeps the minima/maxima per drone (``by_drone`` in
    :meth:`stats`; ``summary`` is over all drones) and names the drone in each warning."""

    name = "monitor"
    consumes, produces = ("odometry",), ("value",)
    FIELDS = ("battery", "height", "gps", "speed")

    def __init__(self, watch: Iterable[str] = ("battery", "height", "gps"), limits: dict[str, float] | None = None,
                 name: str | None = None) -> None:
        super().__init__(name)
        self.watch = list(watch)
        bad = [w for w in self.watch if w not in self.FIELDS + ("camera",)]
        if bad:
            raise ValueError(f"watch: unknown fields {bad}; choose from {list(self.FIELDS)}")
        self.limits = limits or {}
        self.warnings: list[str] = []

    @property
    def summary(self) -> dict[str, dict[str, float]]:
        """Minimum and maximum of each numeric watched field over every drone: ``{field: {"min", "max"}}``."""
        out: dict[str, dict[str, float]] = {}
        for per in self.drone_states().values():
            for k, s in per.items():
                o = out.setdefault(k, dict(s))
                o["min"], o["max"] = min(o["min"], s["min"]), max(o["max"], s["max"])
        return out

    def process(self, odom: dict, meta: Any) -> dict:
        robot = source_robot(odom, meta)
        per: dict[str, dict[str, float]] = self.drone_state(odom, meta, dict)
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
                s = per.setdefault(k, {"min": v, "max": v})
                s["min"], s["max"] = min(s["min"], v), max(s["max"], v)
        who = f"{robot}: " if robot else ""
        if "battery" in self.limits and (vals.get("battery") if vals.get("battery") is not None else 100) \
                < self.limits["battery"]:
            self.warnings.append(f"{who}battery {vals['battery']:.1f}% below {self.limits['battery']}% at "
                                 f"t={odom['t']:.1f}s")
        if "height" in self.limits and vals.get("height", 0) > self.limits["height"]:
            self.warnings.append(f"{who}height {vals['height']:.1f} m above {self.limits['height']} m at "
                                 f"t={odom['t']:.1f}s")
        return {"t": odom["t"], "robot": robot, **vals}

    def stats(self) -> dict:
        return {"summary": self.summary, "by_drone": {r: {k: dict(v) for k, v in per.items()}
                                                      for r, per in self.drone_states().items()},
                "warnings": self.warnings[-5:]}
