"""The built-in ONNX object detector analytics (:class:`ObjectDetector`): camera frames in, detections out."""
from __future__ import annotations

import os
from typing import Any, Iterable, Sequence

import numpy as np

from aerodaas.analytics.base import Analytics
from aerodaas.analytics.contract import current_emissions
from aerodaas.model.types import Detection, FrameMeta
from aerodaas.perception.detector_values import check_detector_values, normalise_classes
from aerodaas.perception.providers import ProviderUnavailableError, providers_setting
from aerodaas.perception.tiling import TiledDetector
from aerodaas.perception.track_records import TrackRecords, track_and_keep

__all__ = ["ObjectDetector"]


class ObjectDetector(Analytics):
    """ONNX object detector on onnxruntime (YOLOX-Nano by default). Input frames (H, W, 3) uint8 BGR; output a
    list of :class:`Detection` (COCO classes, pixel boxes). ``model_path`` may name any compatible ONNX file;
    without it the model is resolved by :func:`aerodaas.perception.model_files.resolve_model` (``$AERODAAS_MODEL_DIR``, cache,
    download) where the driver runs, once, and its bytes travel with the analytics to the node that runs it
    (:class:`aerodaas.perception.model_files.ShippedModel`: cloud nodes need no copy of their own). ``classes`` restricts to the
    model's class names (a plain string is one class; ``[]`` is refused); thresholds are scores in [0, 1].

    Bring your own model: ``model_path`` with ``format`` ``"auto"`` (recognised from the graph),
    ``"yolox"``, ``"nanodet"`` or ``"ultralytics"`` (YOLOv5 / YOLOv8 / YOLO11 ONNX exports,
    :mod:`aerodaas.perception.decoders`); ``class_names`` (else the model's metadata ``names``, else COCO for the
    YOLOX/NanoDet formats); ``input_size=(H, W)`` for an export with dynamic axes; ``upscale=False``: a frame smaller
    than the input is not enlarged (with a dynamic-size model it goes in at its own size, rounded up to multiples of
    32: a 640x480 camera's frames at 480x640, a 1080p camera's at the model's input). ``nms_threshold`` (IoU),
    ``agnostic_nms`` (one NMS over all classes) and ``class_groups`` (``{"vehicle": ["car", "truck", "bus"]}``:
    class-agnostic NMS within a group); ``class_thresholds`` per class. ``tiling``: a
    :class:`aerodaas.perception.tiling.Tiling` for small objects in large frames. Options that need no model file
    (thresholds, ``format``, ``model`` name, ``input_size``, ``threads``, ``batch``, ``upscale``, tiling, tracker) raise
    ValueError naming the field and the value where the detector is built; :meth:`check` checks them again with the
    model's class names and the model file in the pre-flight, before Ray starts (``aerodaas run``/``plan`` exit 2);
    :meth:`process` before :meth:`setup` raises RuntimeError.

    Several drones may share one detector: it remembers nothing between frames (not :attr:`stateful`), and
    :meth:`process_batch` runs the frames of several drones in one onnxruntime call, up to ``batch`` frames, when
    the model's input has a dynamic batch dimension (:attr:`max_batch` is then ``batch``). The shipped YOLOX-Nano
    and NanoDet-Plus exports have a fixed batch of 1: with them :attr:`max_batch` is 1 and :meth:`process_batch`
    is a loop over :meth:`process`. Raises ValueError for ``batch`` < 1.

    ``tracker``: a :class:`aerodaas.perception.tracking.ByteTrackConfig` also runs ByteTrack per drone on the
    detections (the output stays the detections); each drone's geo-located tracks are recorded in a run under
    ``/{robot}/{name}/tracks`` (:mod:`aerodaas.perception.track_records`). The detector is then :attr:`stateful`.

    ``providers``: onnxruntime execution providers in onnxruntime's names, in order of preference — a
    list (``["CUDAExecutionProvider", "CPUExecutionProvider"]``) or a
    :class:`aerodaas.perception.providers.Providers` (``required``, ``num_gpus``, provider ``options``); None: the
    CPU. Names are checked against ``onnxruntime.get_all_providers()`` where the detector is built (ValueError
    naming the field and the value). With a GPU provider its actor asks Ray for ``num_gpus`` (default 1:
    :attr:`num_gpus`) and lands on a node of its compute that has one. On that node a provider its onnxruntime does
    not offer is dropped with a warning and the CPU runs (recorded: an ``onnx_providers`` event on each drone's
    first frame, the summary's analytics line); with ``required=True`` the analytics fails to start instead
    (ProviderUnavailableError), and a run on this machine (no ``--address``) is refused before Ray starts."""

    name = "detector"
    stateful = False
    consumes, produces = ("frame",), ("detections",)

    def __init__(self, model: str = "yolox_nano", model_path: str | None = None,
                 classes: Iterable[str] | str | None = None, score_threshold: float = 0.3,
                 class_thresholds: dict[str, float] | None = None,
                 name: str | None = None, threads: int = 1, batch: int = 8, *, format: str = "auto",
                 nms_threshold: float = 0.45, agnostic_nms: bool = False,
                 class_groups: dict[str, Iterable[str]] | None = None, input_size: tuple[int, int] | None = None,
                 class_names: Sequence[str] | None = None, tiling: Any = None, tracker: Any = None,
                 providers: Any = None, upscale: bool = True) -> None:
        super().__init__(name)
        # what needs no model file fails where the app wrote it; the model's own names in check() (pre-flight)
        check_detector_values(name=self.name, model=model, model_path=model_path, format=format,
                              score_threshold=score_threshold, nms_threshold=nms_threshold,
                              class_thresholds=class_thresholds, input_size=input_size, threads=threads,
                              upscale=upscale)
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
        self.upscale = upscale
        self.class_names = list(class_names) if class_names is not None else None
        self.tiling = tiling
        if tiling is not None:  # a bad slice size fails where the app wrote it (ValueError naming the field)
            tiling.check()
        self.tracker = tracker
        #: the tracks the runtime records (aerodaas.perception.track_records), None without a tracker
        self.track_records = TrackRecords() if tracker is not None else None
        if tracker is not None:
            tracker.check()
            self.stateful = True  # one ByteTracker per drone: each drone's frames must reach the same replica
        self.providers = providers_setting(providers, self.name)
        self.num_gpus = self.providers.ray_gpus() if self.providers is not None else 0.0
        self.session_providers = None  # what the session runs on (SessionProviders), after setup()
        self._providers_told: set[str] = set()  # robots whose events say it already
        self.detector = None
        self.shipped = None  # the model's bytes, read by check() on the driver
        #: the model's format as check() read it from the graph of those bytes (None before check()): the actor's
        #: setup builds the decoder for it without opening the model a second time
        self.checked_format: str | None = None
        self.last_timing: dict[str, float] = {}
        self.n_frames = 0
        self.n_with_dets = 0
        self.n_batched = 0

    def check(self) -> None:
        """Driver side, before any actor starts (called by the pre-flight): check every option
        (:func:`aerodaas.perception.options.check_detector_options`: thresholds, class names against the model's,
        class groups, input size, the model's format) and resolve the model, so a typo or a missing model fails
        with a ValueError naming the field and the value (``aerodaas run`` exits 2)."""
        from aerodaas.perception.model_files import ShippedModel, resolve_model  # lazy: cv2, onnxruntime
        from aerodaas.perception.options import check_detector_options  # lazy: cv2, onnxruntime

        if self.tiling is not None:
            self.tiling.check()
        if self.tracker is not None:
            self.tracker.check()
        self.providers = providers_setting(self.providers, self.name)  # a field changed after construction
        self.num_gpus = self.providers.ray_gpus() if self.providers is not None else 0.0
        if self.model_path is not None and not os.path.isfile(self.model_path):
            raise ValueError(f"analytics {self.name!r}: model_path={str(self.model_path)!r} is not a file")
        self.model_path = str(resolve_model(self.model, self.model_path))  # the actor loads exactly these bytes
        checked = check_detector_options(name=self.name, model=self.model, model_path=self.model_path,
                                         format=self.format,
                                         classes=self.classes, score_threshold=self.score_threshold,
                                         nms_threshold=self.nms_threshold, class_thresholds=self.class_thresholds,
                                         class_groups=self.class_groups, input_size=self.input_size,
                                         class_names=self.class_names, threads=self.threads, upscale=self.upscale)
        self.shipped = ShippedModel.read(self.model_path)
        self.checked_format = checked["format"]

    def setup(self) -> None:
        """On the actor: load the model into an onnxruntime session on ``providers`` (a provider this node lacks:
        a warning and the CPU, recorded as :attr:`session_providers`; required: ProviderUnavailableError naming
        this analytics, the node and the provider) and wrap it for ``tiling``."""
        from aerodaas.perception.options import build_detector  # lazy: cv2 and onnxruntime, on the actor only

        path = self.shipped.path_on_this_node(self.model_path) if self.shipped is not None else self.model_path
        # the shipped bytes are the ones check() read the format of (path_on_this_node loads no other bytes)
        known = getattr(self, "checked_format", None) if self.shipped is not None else None
        try:
            self.detector = build_detector(self.model, model_path=path, format=self.format, checked_format=known,
                                           score_threshold=self.score_threshold, nms_threshold=self.nms_threshold,
                                           classes=self.classes, class_thresholds=self.class_thresholds,
                                           intra_op_threads=self.threads, agnostic_nms=self.agnostic_nms,
                                           class_groups=self.class_groups or None, input_size=self.input_size,
                                           class_names=self.class_names, providers=self.providers,
                                           upscale=self.upscale)
        except ProviderUnavailableError as e:
            raise ProviderUnavailableError(f"analytics {self.name!r}: {e}") from None
        self.session_providers = self.detector.session_providers
        if self.tiling is not None:
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
        self._tell_providers(meta)
        if self.track_records is not None:
            track_and_keep(self, self.track_records, dets, meta, self.tracker)
        return dets

    def _tell_providers(self, meta: FrameMeta | None) -> None:
        """With ``providers`` set: an ``onnx_providers`` event on the first frame of each drone (requested, used,
        the fallback message or None, the node's host), recorded on ``/<robot>/events``."""
        if self.providers is None or self.session_providers is None:
            return
        robot = getattr(meta, "robot_id", None) or ""
        if robot in self._providers_told:
            return
        self._providers_told.add(robot)
        self.emit_event("onnx_providers", **self.session_providers.as_dict())

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
        em = current_emissions(self)
        for j, (_, meta) in enumerate(items):
            if em is not None:
                em.item = j  # the event belongs to this drone's frame (Analytics.process_batch)
            self._tell_providers(meta)
        if self.track_records is not None:
            for dets, (_, meta) in zip(out, items):
                track_and_keep(self, self.track_records, dets, meta, self.tracker)
        return out

    def stats(self) -> dict:
        """``frames``, ``frames_with_detections`` and ``frames_batched`` (inferred in a call with other frames);
        with ``providers`` set also ``providers`` (used), ``providers_requested``, ``provider_fallback`` (the
        message, or None) and ``host`` (:class:`aerodaas.perception.providers.SessionProviders`)."""
        out = {"frames": self.n_frames, "frames_with_detections": self.n_with_dets,
               "frames_batched": getattr(self, "n_batched", 0)}
        if getattr(self, "providers", None) is not None and self.session_providers is not None:
            out.update(self.session_providers.as_dict())
        return out
