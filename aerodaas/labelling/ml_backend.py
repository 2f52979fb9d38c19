"""``aerodaas label serve``: the detector as a Label Studio ML backend, so Label Studio asks it for pre-labels of the
frames a reviewer opens (or of all tasks at once: Data Manager, "Retrieve Predictions").

The protocol is what Label Studio 1.23's ``ml/api_connector.py`` sends: ``GET /health`` (``{"status": "UP"}``),
``POST /setup`` (``project``, ``schema``: the labelling configuration; answered with the ``model_version``),
``POST /predict`` (``tasks``, ``label_config``; answered with ``{"results": [...]}``, one prediction per task, in
order, each ``{"result": [rectanglelabels...], "score", "model_version"}``) and ``POST /webhook`` (events, ignored).
Only the classes of the project's ``RectangleLabels`` that the model knows are predicted, with that control's
``name``/``toName``. A task's image is read below the local-files document root, or fetched from the Label Studio
server the backend was given (``/data/...`` URLs, with its token); the server binds loopback unless told otherwise.
"""
from __future__ import annotations

import hashlib
import json
import threading
import xml.etree.ElementTree as ET
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote

import cv2
import numpy as np

from aerodaas.labelling.label_studio import LabelStudio, LabelStudioError
from aerodaas.training.label_studio_export import image_ref, local_files_path

__all__ = ["DetectorBackend", "load_detector", "make_server", "MAX_BODY_BYTES"]

#: the largest request body read (bytes)
MAX_BODY_BYTES = 64 << 20


def _controls(label_config: str) -> list[tuple[str, str, list[str]]]:
    """(name, toName, label values) of each ``RectangleLabels`` of a labelling configuration."""
    root = ET.fromstring(label_config)
    return [(rl.get("name", "label"), rl.get("toName", "image"), [lab.get("value") for lab in rl.iter("Label")])
            for rl in root.iter("RectangleLabels")]


class DetectorBackend:
    """Predictions of ``detector`` (an :class:`aerodaas.perception.detect.YoloxDetector`: ``detect(image)`` returns
    detections with ``class_name``, ``score`` and a pixel ``box``) as Label Studio results. ``root``: the
    local-files document root; ``studio``: the Label Studio client other images are fetched with (or None)."""

    def __init__(self, detector, model_version: str, root: Path | None = None, studio: LabelStudio | None = None):
        self.detector, self.model_version = detector, model_version
        self.root = root.resolve() if root else None
        self.studio = studio
        self._lock = threading.Lock()  # one onnxruntime session: one frame at a time

    def _image(self, task: dict) -> np.ndarray:
        ref = image_ref(task)
        rel = local_files_path(ref)
        data = None
        if rel is not None and self.root is not None:
            f = (self.root / unquote(rel)).resolve()
            if self.root in f.parents and f.is_file():
                data = f.read_bytes()
        if data is None:
            if self.studio is None or not ref.startswith("/"):
                raise LabelStudioError(f"task {task.get('id')}: image {ref!r} is neither below --document-root "
                                       f"nor fetchable (give --url and a token)")
            data = self.studio.download(ref)
        im = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        if im is None:
            raise LabelStudioError(f"task {task.get('id')}: image {ref!r} cannot be decoded")
        return im

    def predict(self, tasks: list, label_config: str) -> list[dict]:
        """One prediction per task of ``tasks``, in order (module docstring). Raises :class:`LabelStudioError`
        for a task whose image cannot be had, ValueError for a labelling configuration without boxes."""
        controls = _controls(label_config)
        if not controls:
            raise ValueError("label_config has no RectangleLabels: nothing to predict")
        name, to_name, wanted = controls[0]
        out = []
        for task in tasks:
            im = self._image(task)
            h, w = im.shape[:2]
            with self._lock:
                dets = [d for d in self.detector.detect(im) if d.class_name in wanted]
            result = [{"type": "rectanglelabels", "from_name": name, "to_name": to_name, "original_width": w,
                       "original_height": h, "score": float(d.score),
                       "value": {"x": 100 * d.box[0] / w, "y": 100 * d.box[1] / h,
                                 "width": 100 * (d.box[2] - d.box[0]) / w, "height": 100 * (d.box[3] - d.box[1]) / h,
                                 "rotation": 0, "rectanglelabels": [d.class_name]}} for d in dets]
            score = float(np.mean([d.score for d in dets])) if dets else 0.0
            out.append({"result": result, "score": score, "model_version": self.model_version})
        return out


def load_detector(model: Path | None, score_threshold: float):
    """The detector ``serve`` predicts with: an :class:`aerodaas.perception.detect.AerialDetector` of ``model`` (a
    YOLOX ONNX file; None: the shipped aerial_nano) keeping boxes of at least ``score_threshold`` (0 to 1), and its
    model version ``STEM@SHA256[:12]`` of the file. Raises :class:`LabelStudioError` naming ``--model`` for a file
    that is missing or no usable detector."""
    from aerodaas.perception.detect import AerialDetector  # lazy: onnxruntime

    try:
        det = AerialDetector(model, score_threshold=score_threshold)
    except (OSError, ValueError) as e:
        raise LabelStudioError(f"--model {str(model)!r}: {e}") from None
    path = Path(det.model_path)
    return det, f"{path.stem}@{hashlib.sha256(path.read_bytes()).hexdigest()[:12]}"


class _Handler(BaseHTTPRequestHandler):
    server_version = "aerodaas-ml-backend"

    def _reply(self, code: int, doc: dict) -> None:
        body = json.dumps(doc).encode()
        self.send_response(code)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def do_GET(self):  # noqa: N802 - http.server's name
        if self.path.rstrip("/") == "/health":
            self._reply(200, {"status": "UP", "model_class": "aerodaas", "model_version":
                              self.server.backend.model_version})
        else:
            self._reply(404, {"error": f"no such endpoint {self.path}"})

    def do_POST(self):  # noqa: N802 - http.server's name
        n = int(self.headers.get("Content-Length") or 0)
        if n > MAX_BODY_BYTES:
            return self._reply(413, {"error": f"request body of {n} bytes is over {MAX_BODY_BYTES}"})
        try:
            doc = json.loads(self.rfile.read(n) or b"{}")
        except ValueError as e:
            return self._reply(400, {"error": f"request body is not JSON ({e})"})
        backend, path = self.server.backend, self.path.rstrip("/")
        if path == "/setup":
            return self._reply(200, {"model_version": backend.model_version})
        if path == "/webhook":
            return self._reply(200, {"status": "ok"})
        if path != "/predict":
            return self._reply(404, {"error": f"no such endpoint {self.path}"})
        try:
            results = backend.predict(list(doc.get("tasks") or []), str(doc.get("label_config") or ""))
        except (LabelStudioError, ValueError, ET.ParseError) as e:
            return self._reply(400, {"error": str(e)})
        self._reply(200, {"results": results, "model_version": backend.model_version})


def make_server(backend: DetectorBackend, host: str = "127.0.0.1", port: int = 9090) -> ThreadingHTTPServer:
    """An HTTP server of ``backend`` bound to ``host``:``port`` (0: any free port); call ``serve_forever``.
    Raises OSError when the address cannot be bound."""
    srv = ThreadingHTTPServer((host, port), _Handler)
    srv.daemon_threads = True
    srv.backend = backend
    return srv
