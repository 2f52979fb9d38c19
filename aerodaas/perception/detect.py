"""Object detection on camera frames with small COCO ONNX models (CPU, onnxruntime).

Two detectors share one interface (``detect(image_bgr) -> list[Detection]``, ``detect_batch(images)`` plus
``last_timing``):

* :class:`YoloxDetector` -- YOLOX-Nano, 416x416 input (Megvii YOLOX, Apache-2.0).
* :class:`NanoDetDetector` -- NanoDet-Plus-m 1.5x, 416x416 input (RangiLyu NanoDet / OpenCV model zoo, Apache-2.0).

Model files are located by :func:`~aerodaas.perception.model_files.resolve_model` (explicit path, ``$AERODAAS_MODEL_DIR``,
the user cache, then a download pinned to a commit and verified by sha256; :mod:`aerodaas.perception.model_files`).

Batching: ``detect_batch`` runs several images (e.g. the latest frames of several drones) in one onnxruntime call
when the model's input has a dynamic batch dimension (``batch_dynamic``); the shipped YOLOX-Nano and NanoDet-Plus
exports have a fixed batch of 1 (input ``(1, 3, 416, 416)``, and batch-1 ``Reshape`` constants inside the graph),
so with them ``detect_batch`` is a loop over ``detect`` (same results, no speed-up).

Conventions: images are ``(H, W, 3)`` ``uint8`` **BGR** arrays (what ``cv2.imread`` returns); boxes are
``(x0, y0, x1, y1)`` in pixels of the image passed to ``detect`` (origin top-left, clipped to ``[0, W] x [0, H]``);
times are milliseconds.
"""
from __future__ import annotations

import logging
import os
import time
from typing import Iterable, Sequence

import cv2
import numpy as np

from aerodaas.model.types import COCO_CLASSES, Detection
from aerodaas.perception.model_meta import metadata_imgsz, metadata_names
from aerodaas.perception.detector_values import check_input_size
from aerodaas.perception.providers import Providers, open_session

__all__ = [
    "YoloxDetector", "NanoDetDetector", "AerialDetector", "make_detector", "DETECTORS",
]

log = logging.getLogger(__name__)

from aerodaas.perception.model_files import _ALIASES, resolve_model


# ----------------------------------------------------------------------------------------------------------------
# Detectors
# ----------------------------------------------------------------------------------------------------------------

_CLASS_INDEX = {n: i for i, n in enumerate(COCO_CLASSES)}


def _check_image(image: np.ndarray) -> None:
    if not isinstance(image, np.ndarray):
        raise ValueError(f"image must be a numpy array of shape (H, W, 3) and dtype uint8, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise ValueError(f"image must have dtype uint8 (BGR 0-255), got dtype {image.dtype} with shape {image.shape}")
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 1 or image.shape[1] < 1:
        raise ValueError(
            f"image must have shape (H, W, 3) (BGR), got shape {image.shape}; convert grey/BGRA with cv2.cvtColor"
        )


def _some(names: Sequence[str], n: int = 12) -> str:
    return ", ".join(names[:n]) + (f", ... ({len(names)} in all)" if len(names) > n else "")





def _nms(boxes: np.ndarray, scores: np.ndarray, iou_threshold: float) -> np.ndarray:
    """Greedy non-maximum suppression on ``(N, 4)`` x0y0x1y1 boxes; returns kept indices, best score first."""
    x0, y0, x1, y1 = boxes.T
    areas = np.maximum(x1 - x0, 0) * np.maximum(y1 - y0, 0)
    order = np.argsort(-scores, kind="stable")
    keep = []
    while order.size:
        i = order[0]
        keep.append(i)
        rest = order[1:]
        w = np.maximum(0.0, np.minimum(x1[i], x1[rest]) - np.maximum(x0[i], x0[rest]))
        h = np.maximum(0.0, np.minimum(y1[i], y1[rest]) - np.maximum(y0[i], y0[rest]))
        inter = w * h
        iou = inter / np.maximum(areas[i] + areas[rest] - inter, 1e-9)
        order = rest[iou <= iou_threshold]
    return np.asarray(keep, dtype=np.int64)


class _OnnxDetector:
    """Shared machinery: session creation, thresholds, class filter, class-aware NMS, Detection output."""

    model_name: str = ""
    _pre_nms_top_k = 1000

    def __init__(
        self,
        model_path: str | os.PathLike | None = None,
        *,
        score_threshold: float = 0.3,
        nms_threshold: float = 0.45,
        classes: Iterable[str] | str | None = None,
        class_thresholds: dict[str, float] | None = None,
        intra_op_threads: int = 1,
        agnostic_nms: bool = False,
        class_groups: dict[str, Iterable[str]] | None = None,
        input_size: tuple[int, int] | None = None,
        class_names: Sequence[str] | None = None,
        providers: Providers | None = None,
        upscale: bool = True,
    ) -> None:
        if not isinstance(upscale, bool):
            raise ValueError(f"upscale must be True or False, got {upscale!r}")
        self.upscale = upscale
        if not 0.0 <= score_threshold <= 1.0:
            raise ValueError(f"score_threshold must be within [0, 1], got {score_threshold}")
        if not 0.0 <= nms_threshold <= 1.0:
            raise ValueError(f"nms_threshold must be within [0, 1], got {nms_threshold}")
        if int(intra_op_threads) < 0:
            raise ValueError(f"intra_op_threads must be >= 0 (0 = onnxruntime default), got {intra_op_threads}")
        self.score_threshold = float(score_threshold)
        self.nms_threshold = float(nms_threshold)
        self.agnostic_nms = bool(agnostic_nms)

        self.model_path = resolve_model(self.model_name, model_path)
        self._open_session(int(intra_op_threads), input_size, providers)
        self._init_classes(class_names, class_thresholds, classes, class_groups)
        self.last_timing: dict[str, float] = {"preprocess_ms": 0.0, "inference_ms": 0.0, "postprocess_ms": 0.0}
        self.last_batch = 1  # most images in one onnxruntime call of the last detect / detect_batch
        self.last_batched = 0  # images of the last detect_batch that shared an onnxruntime call with others

    def _open_session(self, intra_op_threads: int, input_size: tuple[int, int] | None,
                      providers: Providers | None = None) -> None:
        """The onnxruntime session (``intra_op_threads`` threads; on ``providers``, None: the CPU, see
        :func:`aerodaas.perception.providers.open_session`: what it runs on is :attr:`session_providers`) and its
        input: name, (H, W) size (the model's fixed one, ``input_size``, or the subclass's default), whether the
        batch is dynamic, the output names. Raises ValueError for a model whose input is not NCHW or an
        ``input_size`` its fixed input contradicts, ProviderUnavailableError for a required provider missing."""
        import onnxruntime as ort  # lazy: heavy onnxruntime

        so = ort.SessionOptions()
        so.intra_op_num_threads = intra_op_threads
        so.inter_op_num_threads = 1
        so.log_severity_level = 3  # the NanoDet export triggers one harmless warning per initializer
        self.intra_op_threads = intra_op_threads
        self.session, self.session_providers = open_session(str(self.model_path), so, providers,
                                                            f"model {os.path.basename(self.model_path)}")
        inp = self.session.get_inputs()[0]
        self.input_name: str = inp.name
        shape = inp.shape
        if len(shape) != 4:
            raise ValueError(f"{self.model_path}: expected an NCHW input, got {inp.name} {shape}")
        fixed_hw = all(isinstance(d, int) for d in shape[2:])
        self.dynamic_hw = not fixed_hw
        if input_size is not None:
            ih, iw = check_input_size(input_size)
            if fixed_hw and (ih, iw) != (int(shape[2]), int(shape[3])):
                raise ValueError(f"input_size={tuple(input_size)!r} but {self.model_path} has a fixed input "
                                 f"{tuple(shape[2:])} (H, W); omit input_size or export with dynamic axes")
            self.input_hw: tuple[int, int] = (ih, iw)
        elif fixed_hw:
            self.input_hw = (int(shape[2]), int(shape[3]))
        else:
            self.input_hw = self._default_input_hw(shape)
        # onnxruntime reports a symbolic dimension as its name (str) and an unknown one as None; only then may the
        # batch differ from the exported one
        self.batch_dynamic: bool = not isinstance(shape[0], int)
        self.output_names = [o.name for o in self.session.get_outputs()]

    def _init_classes(self, class_names: Sequence[str] | None, class_thresholds: dict[str, float] | None,
                      classes: Iterable[str] | str | None, class_groups: dict[str, Iterable[str]] | None) -> None:
        """Class names (given, or the model's), per-class score thresholds (+inf for the classes left out by
        ``classes``) and each class's NMS group. Raises ValueError naming an unknown class or a threshold outside
        [0, 1]."""
        names = tuple(class_names) if class_names is not None else self._model_class_names()
        self.class_names: tuple[str, ...] = tuple(str(n) for n in names)
        index = {n: i for i, n in enumerate(self.class_names)}
        kind = "COCO class" if self.class_names == tuple(COCO_CLASSES) else "class"
        self._class_index = index
        # Per-class score thresholds; excluded classes get +inf so nothing passes.
        thr = np.full(len(self.class_names), self.score_threshold, dtype=np.float32)
        for cname, value in (class_thresholds or {}).items():
            if cname not in index:
                raise ValueError(f"class_thresholds: unknown {kind} {cname!r} (the model's classes: "
                                 f"{_some(self.class_names)})")
            if not 0.0 <= float(value) <= 1.0:
                raise ValueError(f"class_thresholds[{cname!r}] must be within [0, 1], got {value}")
            thr[index[cname]] = float(value)
        self.classes: tuple[str, ...] | None = None
        if classes is not None:
            if isinstance(classes, str):
                classes = [classes]
            self.classes = tuple(classes)
            if not self.classes:
                raise ValueError("classes must name at least one class (or be None for all classes)")
            unknown = [c for c in self.classes if c not in index]
            if unknown:
                raise ValueError(f"classes: unknown {kind} name(s) {unknown} (the model's classes: "
                                 f"{_some(self.class_names)})")
            mask = np.ones(len(self.class_names), dtype=bool)
            mask[[index[c] for c in self.classes]] = False
            thr[mask] = np.inf
        self.class_thresholds = dict(class_thresholds or {})
        self._thr = thr
        # NMS group of each class: its own index, or the group's (class_groups), or one group for all (agnostic)
        group = np.arange(len(self.class_names), dtype=np.int64)
        self.class_groups = {g: tuple(m) for g, m in (class_groups or {}).items()}
        for gi, (gname, members) in enumerate(self.class_groups.items()):
            bad = [m for m in members if m not in index]
            if bad or not members:
                raise ValueError(f"class_groups[{gname!r}]: unknown class name(s) {bad or members} (the model's "
                                 f"classes: {_some(self.class_names)})")
            for m in members:
                group[index[m]] = len(self.class_names) + gi
        if self.agnostic_nms:
            group[:] = 0
        self._nms_group = group

    def _model_class_names(self) -> Sequence[str]:
        """The class names the model's metadata carries (``names``, :func:`metadata_names`: what
        ``aerodaas train detector`` writes), else COCO's 80."""
        names = metadata_names(self.session.get_modelmeta().custom_metadata_map)
        return COCO_CLASSES if names is None else names

    def _default_input_hw(self, shape) -> tuple[int, int]:
        """The input size a dynamic model carries in its metadata (``imgsz``: ``"[H, W]"`` or ``"N"``, as
        Ultralytics and ``aerodaas train detector`` write it), else ValueError asking for ``input_size``."""
        hw = metadata_imgsz(self.session.get_modelmeta().custom_metadata_map)
        if hw is not None:
            return check_input_size(hw)
        raise ValueError(f"{self.model_path}: the input {self.input_name} {shape} has dynamic height/width; give "
                         f"input_size=(H, W)")

    def _scale_and_canvas(self, h: int, w: int) -> tuple[float, tuple[int, int]]:
        """The resize factor of an ``h`` x ``w`` frame and the ``(H, W)`` input it is letterboxed into: the model's
        input; with ``upscale=False``, a frame smaller than that input keeps its scale (1.0) and, for a model with
        dynamic height/width, goes into the smallest input of multiples of 32 that holds it (a 640x480 frame: 480x640)."""
        ih, iw = self.input_hw
        r = min(ih / h, iw / w)
        if self.upscale or r <= 1.0:
            return r, (ih, iw)
        return 1.0, ((-(-h // 32) * 32, -(-w // 32) * 32) if self.dynamic_hw else (ih, iw))

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(model_path={str(self.model_path)!r}, score_threshold={self.score_threshold}, "
                f"nms_threshold={self.nms_threshold}, classes={self.classes}, agnostic_nms={self.agnostic_nms}, "
                f"input_hw={self.input_hw}, "
                f"intra_op_threads={self.intra_op_threads})")

    # Subclasses implement: _preprocess(image) -> (blob, ctx); _candidates(outputs, min_score, ctx) -> (anchor
    # indices, (K, 80) class scores) for anchors that may reach min_score; _boxes(outputs, idx, ctx) -> (K, 4) x0y0x1y1
    # boxes in model-input pixels; _unmap(boxes, ctx) -> boxes in pixels of the original image.

    def detect(self, image_bgr: np.ndarray) -> list[Detection]:
        """Detect COCO objects in one ``(H, W, 3)`` ``uint8`` BGR image of any size.

        Returns :class:`~aerodaas.model.types.Detection` objects sorted by descending score, boxes
        ``(x0, y0, x1, y1)`` in pixels of ``image_bgr`` clipped to ``[0, W] x [0, H]``. Only classes in
        ``classes`` (if given) whose score reaches their threshold are kept, then class-aware NMS is applied.
        Sets ``self.last_timing`` (``preprocess_ms``, ``inference_ms``, ``postprocess_ms``; ``time.perf_counter``).

        Raises ``ValueError`` if ``image_bgr`` is not a 3-channel ``uint8`` array (message names shape and dtype).
        """
        t0 = time.perf_counter()
        _check_image(image_bgr)
        blob, ctx = self._preprocess(image_bgr)
        t1 = time.perf_counter()
        outputs = self.session.run(None, {self.input_name: blob})
        t2 = time.perf_counter()
        dets = self._postprocess(outputs, ctx, image_bgr.shape[:2])
        t3 = time.perf_counter()
        self.last_batch = 1
        self.last_timing = {
            "preprocess_ms": (t1 - t0) * 1e3,
            "inference_ms": (t2 - t1) * 1e3,
            "postprocess_ms": (t3 - t2) * 1e3,
        }
        return dets

    __call__ = detect

    def detect_batch(self, images: list[np.ndarray], max_batch: int = 8) -> list[list[Detection]]:
        """Detect in several images (each ``(H, W, 3)`` ``uint8`` BGR, sizes may differ); returns one detection list
        per image, in order, each exactly as :meth:`detect` returns it for that image alone.

        With a model whose input batch dimension is dynamic (``batch_dynamic``: the shipped ``aerial_nano``), the
        images go through onnxruntime together, up to ``max_batch`` consecutive ones per call whose input has one
        size (an ``(n, 3, h, w)`` input, outputs split along axis 0; with ``upscale=False`` the size follows the
        frame, so a change of frame size starts a new call); with a fixed-batch model (the COCO ``yolox_nano`` and
        ``nanodet_plus_m_416``: ``(1, 3, 416, 416)``) this is a loop over :meth:`detect`.
        ``last_timing`` then holds the whole call's times (ms), ``last_batch`` the most images in one onnxruntime
        call and ``last_batched`` how many images shared a call with others. Raises ``ValueError`` (naming the image's index, shape and dtype) before any inference if an image is
        not a 3-channel ``uint8`` array, and ``ValueError`` if ``max_batch`` < 1."""
        if int(max_batch) < 1:
            raise ValueError(f"max_batch must be >= 1, got {max_batch}")
        for i, im in enumerate(images):
            try:
                _check_image(im)
            except ValueError as e:
                raise ValueError(f"images[{i}]: {e}") from None
        if not self.batch_dynamic or len(images) <= 1:
            out, total = [], {"preprocess_ms": 0.0, "inference_ms": 0.0, "postprocess_ms": 0.0}
            for im in images:
                out.append(self.detect(im))
                for k in total:
                    total[k] += self.last_timing[k]
            self.last_timing, self.last_batch, self.last_batched = total, 1, 0
            return out
        out, self.last_batch, self.last_batched = [], 1, 0
        total = {"preprocess_ms": 0.0, "inference_ms": 0.0, "postprocess_ms": 0.0}
        lo, pending = 0, None
        while lo < len(images):
            t0 = time.perf_counter()
            # one call takes up to max_batch images whose input has one size (with upscale=False it follows the frame)
            pre = [pending or self._preprocess(images[lo])]
            pending = None
            while len(pre) < int(max_batch) and lo + len(pre) < len(images):
                nxt = self._preprocess(images[lo + len(pre)])
                if nxt[0].shape != pre[0][0].shape:
                    pending = nxt
                    break
                pre.append(nxt)
            chunk = images[lo:lo + len(pre)]
            lo += len(pre)
            blob = np.concatenate([b for b, _ in pre], axis=0)
            t1 = time.perf_counter()
            outputs = self.session.run(None, {self.input_name: blob})
            t2 = time.perf_counter()
            for i, (im, (_, ctx)) in enumerate(zip(chunk, pre)):
                out.append(self._postprocess([o[i:i + 1] for o in outputs], ctx, im.shape[:2]))
            t3 = time.perf_counter()
            total["preprocess_ms"] += (t1 - t0) * 1e3
            total["inference_ms"] += (t2 - t1) * 1e3
            total["postprocess_ms"] += (t3 - t2) * 1e3
            self.last_batch = max(self.last_batch, len(chunk))
            self.last_batched += len(chunk) if len(chunk) > 1 else 0
        self.last_timing = total
        return out

    def _postprocess(self, outputs, ctx, hw: tuple[int, int]) -> list[Detection]:
        idx, scores = self._candidates(outputs, float(self._thr.min()), ctx)
        if idx.size == 0:
            return []
        # Zero every score under its class threshold (or of an excluded class); each anchor then votes for its best
        # remaining class, so a filtered-out top class does not hide an eligible second one.
        scores = np.where(scores >= self._thr, scores, 0.0)
        cls = scores.argmax(axis=1)
        conf = scores[np.arange(scores.shape[0]), cls]
        keep = conf > 0.0
        if not keep.any():
            return []
        idx, conf, cls = idx[keep], conf[keep], cls[keep]
        if conf.size > self._pre_nms_top_k:
            top = np.argpartition(-conf, self._pre_nms_top_k)[: self._pre_nms_top_k]
            idx, conf, cls = idx[top], conf[top], cls[top]
        boxes = self._boxes(outputs, idx, ctx)
        boxes = self._unmap(boxes.astype(np.float64), ctx)
        h, w = hw
        np.clip(boxes[:, 0::2], 0.0, float(w), out=boxes[:, 0::2])
        np.clip(boxes[:, 1::2], 0.0, float(h), out=boxes[:, 1::2])
        # NMS per group (class-aware: one group per class; class_groups; agnostic: one group) by offsetting each
        # group into its own disjoint coordinate range.
        offset = self._nms_group[cls].astype(np.float64)[:, None] * (float(max(h, w)) + 1.0)
        kept = _nms(boxes + offset, conf.astype(np.float64), self.nms_threshold)
        return [
            Detection(
                class_id=int(cls[i]),
                class_name=self.class_names[int(cls[i])],
                score=float(min(max(conf[i], 0.0), 1.0)),
                box=(float(boxes[i, 0]), float(boxes[i, 1]), float(boxes[i, 2]), float(boxes[i, 3])),
            )
            for i in kept
        ]


class YoloxDetector(_OnnxDetector):
    """YOLOX-Nano COCO detector (ONNX, CPU via onnxruntime).

    Model contract (``MANIFEST.md`` of the shared data, and the Megvii YOLOX ONNX demo
    ``demo/ONNXRuntime/onnx_inference.py`` with ``yolox/utils/demo_utils.py``): input ``images`` float32
    ``(1, 3, 416, 416)``, BGR 0-255 (no mean/std), letterboxed as ``preproc`` does (resize keeping the aspect
    ratio with bilinear interpolation, top-left aligned, bottom/right padded with 114). Output ``output``
    ``(1, 3549, 85)`` raw, decoded as ``demo_postprocess``: on grids of strides 8/16/32 (52x52 + 26x26 + 13x13),
    ``xy = (p_xy + grid) * stride``, ``wh = exp(p_wh) * stride`` (centre/size in input pixels),
    ``score = objectness * class_prob`` (both already sigmoid in the export).

    Args:
        model_path: ONNX file; ``None`` resolves ``"yolox_nano"`` with :func:`resolve_model`.
        score_threshold: minimum ``obj * cls`` score in [0, 1].
        nms_threshold: IoU above which a lower-scored box of the same class is suppressed.
        classes: COCO class names to report (all if ``None``).
        class_thresholds: per-class score thresholds overriding ``score_threshold``, by COCO name.
        intra_op_threads: onnxruntime ``intra_op_num_threads`` (0 = onnxruntime default, all cores).
        agnostic_nms: one NMS over all classes (a vehicle is not reported both as "car" and "truck").
        class_groups: ``{"vehicle": ["car", "truck", "bus"]}``: NMS is class-agnostic within each group (the
            detections keep their own class names); other classes stay class-aware.
        input_size: ``(H, W)`` pixels, multiples of 32, for a model exported with dynamic height/width (must equal
            the model's own for a fixed-size one).
        class_names: the model's class names in output order (default: COCO's 80, or the model's metadata).
        upscale: ``False``: a frame smaller than the input is not enlarged; it keeps its scale and, with dynamic
            height/width, goes into the smallest input of multiples of 32 holding it (a 640x480 frame at 480x640,
            a 1920x1080 one still at the model's input). The model card of ``aerial_nano`` measures why: enlarged
            1.5x, the simulated car was found in 62 % of frames, at its own size in 100 %.

    Raises ``ValueError`` for out-of-range thresholds, unknown class names or a bad ``input_size``, and the errors of
    :func:`resolve_model` when the model cannot be found. ``detect`` is documented on the base class.
    """

    model_name = "yolox_nano"
    strides = (8, 16, 32)

    def __init__(self, model_path: str | os.PathLike | None = None, **kwargs) -> None:
        super().__init__(model_path, **kwargs)
        self._grids: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}  # (H, W) input -> (grid, stride)
        self._pad = np.full((*self.input_hw, 3), 114, dtype=np.uint8)

    def _grid_for(self, hw: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """Anchor cells ``(A, 2)`` and strides ``(A, 1)`` of an ``(H, W)`` input, strides 8/16/32 in order."""
        if hw not in self._grids:
            grids, strides = [], []
            for s in self.strides:
                gh, gw = hw[0] // s, hw[1] // s
                xv, yv = np.meshgrid(np.arange(gw), np.arange(gh))
                grids.append(np.stack((xv, yv), axis=-1).reshape(-1, 2))
                strides.append(np.full((gh * gw, 1), s))
            self._grids[hw] = (np.concatenate(grids).astype(np.float32), np.concatenate(strides).astype(np.float32))
        return self._grids[hw]

    def _preprocess(self, image: np.ndarray):
        h, w = image.shape[:2]
        r, hw = self._scale_and_canvas(h, w)
        nw, nh = max(1, int(w * r)), max(1, int(h * r))
        padded = self._pad.copy() if hw == self.input_hw else np.full((*hw, 3), 114, dtype=np.uint8)
        padded[:nh, :nw] = cv2.resize(image, (nw, nh), interpolation=cv2.INTER_LINEAR)
        blob = np.ascontiguousarray(padded.transpose(2, 0, 1)[None], dtype=np.float32)
        return blob, (nw / w, nh / h, hw)

    def _candidates(self, outputs, min_score: float, ctx):
        p = outputs[0][0]
        nc = len(self.class_names)
        n = self._grid_for(ctx[2])[0].shape[0]
        if p.shape != (n, 5 + nc):
            raise RuntimeError(f"{self.model_path}: output shape {p.shape}, expected ({n}, {5 + nc}) for {nc} classes")
        idx = np.flatnonzero(p[:, 4] >= min_score)  # score = obj * cls <= obj
        return idx, p[idx, 4:5] * p[idx, 5:]

    def _boxes(self, outputs, idx: np.ndarray, ctx) -> np.ndarray:
        p = outputs[0][0][idx]
        grid, strides = self._grid_for(ctx[2])
        stride = strides[idx]
        xy = (p[:, :2] + grid[idx]) * stride
        wh = np.exp(p[:, 2:4]) * stride
        return np.concatenate([xy - wh / 2, xy + wh / 2], axis=1)

    @staticmethod
    def _unmap(boxes: np.ndarray, ctx) -> np.ndarray:
        sx, sy = ctx[0], ctx[1]
        boxes[:, 0::2] /= sx
        boxes[:, 1::2] /= sy
        return boxes


class NanoDetDetector(_OnnxDetector):
    """NanoDet-Plus-m 1.5x 416 COCO detector (ONNX, CPU via onnxruntime); same interface as :class:`YoloxDetector`.

    Model contract (``MANIFEST.md``; OpenCV model zoo ``models/object_detection_nanodet/nanodet.py`` and
    ``demo.py``): input ``input.1`` float32 ``(1, 3, 416, 416)``, BGR, ``(x - mean) / std`` with mean
    ``(103.53, 116.28, 123.675)`` and std ``(57.375, 57.12, 58.395)`` (the NanoDet training normalisation, in
    BGR order; the zoo demo feeds RGB, which we do not copy). Letterbox as the zoo ``letterbox``: resize keeping
    the aspect ratio (``INTER_AREA``), **centred**, padded with 0 before normalisation. Outputs, matched by shape:
    per stride 8/16/32 class scores ``(1, N, 80)`` (already sigmoid) and box distributions ``(1, N, 32)``
    (Distribution Focal Loss, ``reg_max = 7``: for each of left/top/right/bottom, ``distance = softmax(8 bins) .
    [0..7] * stride``), measured from the prior point ``(col * stride + (stride - 1) / 2, row * stride +
    (stride - 1) / 2)`` as in the zoo ``nanodet.py``. (Upstream NanoDet-Plus training code puts the priors at
    ``col * stride`` without the half-cell offset; for *this* export the zoo offset is the right one: with it,
    detections on a horizontally/vertically flipped frame flip back to within ~1-2 px, without it they are off by
    ~15 px, measured on the shared aerial crops.)

    Arguments and errors as :class:`YoloxDetector` (``model_path=None`` resolves ``"nanodet_plus_m_416"``).
    """

    model_name = "nanodet_plus_m_416"
    strides = (8, 16, 32)
    reg_max = 7
    mean = np.array([103.53, 116.28, 123.675], dtype=np.float32)
    std = np.array([57.375, 57.12, 58.395], dtype=np.float32)

    def __init__(self, model_path: str | os.PathLike | None = None, **kwargs) -> None:
        super().__init__(model_path, **kwargs)
        ih, iw = self.input_hw
        levels = {}
        for s in self.strides:
            gh, gw = ih // s, iw // s
            xv, yv = np.meshgrid(np.arange(gw) * s, np.arange(gh) * s)
            centers = np.stack((xv.ravel(), yv.ravel()), axis=-1).astype(np.float32) + 0.5 * (s - 1)
            levels[gh * gw] = (s, centers)
        # Pair each stride's class/box outputs by their anchor count N and last dimension (80 vs 4*(reg_max+1)).
        cls_idx, reg_idx = {}, {}
        for k, o in enumerate(self.session.get_outputs()):
            shp = o.shape
            n, c = shp[-2], shp[-1]
            if n in levels and c == len(self.class_names):
                cls_idx[n] = k
            elif n in levels and c == 4 * (self.reg_max + 1):
                reg_idx[n] = k
        if set(cls_idx) != set(levels) or set(reg_idx) != set(levels):
            raise ValueError(
                f"{self.model_path}: outputs {[(o.name, o.shape) for o in self.session.get_outputs()]} do not match "
                f"the NanoDet layout (per stride (1, N, 80) scores and (1, N, 32) box distributions)"
            )
        order = sorted(levels, reverse=True)  # stride 8 first
        self._cls_out = [cls_idx[n] for n in order]
        self._reg_out = [reg_idx[n] for n in order]
        self._centers = np.concatenate([levels[n][1] for n in order])
        self._anchor_stride = np.concatenate([np.full((n, 1), levels[n][0], np.float32) for n in order])
        self._project = np.arange(self.reg_max + 1, dtype=np.float32)
        # uint8 -> normalised float32 lookup table per BGR channel, shape (3, 256)
        self._lut = ((np.arange(256, dtype=np.float32)[None, :] - self.mean[:, None]) / self.std[:, None]).astype(
            np.float32)

    def _preprocess(self, image: np.ndarray):
        ih, iw = self.input_hw  # its anchor centres are laid out for this input: upscale=False only keeps the scale
        h, w = image.shape[:2]
        r = self._scale_and_canvas(h, w)[0]
        nw, nh = max(1, min(iw, int(w * r))), max(1, min(ih, int(h * r)))
        top, left = (ih - nh) // 2, (iw - nw) // 2
        canvas = np.zeros((ih, iw, 3), dtype=np.uint8)
        canvas[top:top + nh, left:left + nw] = cv2.resize(image, (nw, nh), interpolation=cv2.INTER_AREA)
        blob = np.empty((1, 3, ih, iw), dtype=np.float32)
        for c in range(3):  # (x - mean) / std through a lookup table: same values, ~5x faster than float maths
            blob[0, c] = self._lut[c][canvas[:, :, c]]
        return blob, (left, top, nw / w, nh / h)

    def _candidates(self, outputs, min_score: float, ctx=None):
        scores = np.concatenate([outputs[k][0] for k in self._cls_out])
        idx = np.flatnonzero(scores.max(axis=1) >= min_score)
        return idx, scores[idx]

    def _boxes(self, outputs, idx: np.ndarray, ctx=None) -> np.ndarray:
        reg = np.concatenate([outputs[k][0] for k in self._reg_out])[idx].reshape(-1, 4, self.reg_max + 1)
        reg = np.exp(reg - reg.max(axis=-1, keepdims=True))
        dist = (reg / reg.sum(axis=-1, keepdims=True)) @ self._project * self._anchor_stride[idx]  # (K, 4): l t r b
        centers = self._centers[idx]
        return np.concatenate([centers - dist[:, :2], centers + dist[:, 2:]], axis=1)

    @staticmethod
    def _unmap(boxes: np.ndarray, ctx) -> np.ndarray:
        left, top, sx, sy = ctx
        boxes[:, 0::2] = (boxes[:, 0::2] - left) / sx
        boxes[:, 1::2] = (boxes[:, 1::2] - top) / sy
        return boxes


class AerialDetector(YoloxDetector):
    """The aerial detector shipped with AeroDaaS (``aerial_nano``: YOLOX-Nano fine-tuned by ``aerodaas train
    detector`` on openly licensed drone imagery; classes ``car``, ``large_vehicle``, ``person``; sources, licences,
    training command and measured quality in ``aerodaas/perception/models/MODEL_CARD.md``). Same contract as
    :class:`YoloxDetector` with dynamic height/width: the default input size is the model's ``imgsz`` metadata
    (``input_size=(H, W)``, multiples of 32, overrides it)."""

    model_name = "aerial_nano"


DETECTORS: dict[str, type[_OnnxDetector]] = {
    "aerial_nano": AerialDetector,
    "yolox_nano": YoloxDetector,
    "nanodet_plus_m_416": NanoDetDetector,
}


def make_detector(name: str = "yolox_nano", **kwargs) -> YoloxDetector | NanoDetDetector:
    """Build a detector by model name (``"yolox_nano"`` / ``"yolox"`` or ``"nanodet_plus_m_416"`` / ``"nanodet"``).

    ``kwargs`` go to the detector's constructor (``model_path``, ``score_threshold``, ``nms_threshold``,
    ``classes``, ``class_thresholds``, ``intra_op_threads``). Raises ``ValueError`` for an unknown name (listing
    the known ones) plus whatever the constructor raises.
    """
    key = _ALIASES.get(name, name)
    if key not in DETECTORS:
        raise ValueError(f"unknown detector {name!r}; known: {', '.join(sorted([*DETECTORS, *_ALIASES]))}")
    return DETECTORS[key](**kwargs)
