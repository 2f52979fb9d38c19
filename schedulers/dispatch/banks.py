"""The models an executor runs, by workload model name: :class:`DetectorBank` (lazily built ONNX detectors,
:func:`aerodaas.perception.detect.make_detector`) and :class:`AnalyticsBank` (an application's analytics objects). Both keep
one instance per thread, since onnxruntime sessions are not meant to be shared across concurrent ``run`` calls."""
from __future__ import annotations

import copy
import threading
from typing import Any, Mapping

__all__ = ["DetectorBank", "AnalyticsBank"]


class DetectorBank:
    """Lazily built ONNX detectors by name, shared by the threads of one executor (one session per name and thread,
    since onnxruntime sessions are not meant to be shared across concurrent ``run`` calls)."""

    def __init__(self, detector_for: Mapping[str, str] | str, detector_kwargs: Mapping[str, Any] | None = None):
        self.detector_for = detector_for
        self.kwargs = dict(detector_kwargs or {})
        self._local = threading.local()

    def name_for(self, model: str) -> str:
        if isinstance(self.detector_for, str):
            return self.detector_for
        try:
            return self.detector_for[model]
        except KeyError:
            raise KeyError(f"no ONNX detector configured for model {model!r} (have {sorted(self.detector_for)})") \
                from None

    def _detector(self, name: str):
        """This thread's detector ``name``, built on first use."""
        from aerodaas.perception.detect import make_detector  # lazy: heavy cv2

        cache = getattr(self._local, "cache", None)
        if cache is None:
            cache = self._local.cache = {}
        det = cache.get(name)
        if det is None:
            det = cache[name] = make_detector(name, **self.kwargs)
        return det

    def prepare(self) -> None:
        """Build this thread's detector of every configured name now rather than during its first task (opening an
        ONNX session took 6 s on a loaded 2-core machine, which made the run's first frame late). Raises what
        :func:`~aerodaas.perception.detect.make_detector` raises."""
        names = [self.detector_for] if isinstance(self.detector_for, str) else sorted(set(self.detector_for.values()))
        for name in names:
            self._detector(name)

    def detect(self, model: str, frame) -> list:
        return self._detector(self.name_for(model)).detect(frame)

    def run(self, model: str, frame, meta: Any = None) -> list:
        """The detections of ``model``'s detector on ``frame`` (``meta`` unused)."""
        return self.detect(model, frame)


class AnalyticsBank:
    """Runs an application's analytics objects (:class:`aerodaas.analytics.core.Analytics`) by model name, for the
    executors of scheduled analytics. Each thread gets its own copy of an analytics (``setup()`` once per copy), so
    an onnxruntime session is never shared by concurrent calls; with ``shared=True`` the given objects themselves
    are used, already set up by the caller (one executor thread: the edge host's own analytics). :meth:`run` returns ``process(frame, meta)`` and keeps the analytics'
    ``last_timing`` in ``self.last_timing`` of the thread (inference ms, when the analytics reports it)."""

    def __init__(self, analytics: Mapping[str, Any], shared: bool = False) -> None:
        if not analytics:
            raise ValueError("an AnalyticsBank needs at least one analytics (model name -> Analytics)")
        self.analytics = dict(analytics)
        self.shared = shared  # the caller has set the objects up (they live in its host)
        self._local = threading.local()

    def _get(self, model: str):
        try:
            proto = self.analytics[model]
        except KeyError:
            raise KeyError(f"no analytics for model {model!r} (have {sorted(self.analytics)})") from None
        if self.shared:
            return proto
        cache = getattr(self._local, "cache", None)
        if cache is None:
            cache = self._local.cache = {}
        obj = cache.get(model)
        if obj is None:
            obj = cache[model] = copy.deepcopy(proto)
            obj.setup()
        return obj

    def prepare(self) -> None:
        """Copy and set up this thread's instance of every analytics now rather than during its first task (see
        :meth:`DetectorBank.prepare`); nothing to do with ``shared``. Raises what ``setup()`` raises."""
        for model in self.analytics:
            self._get(model)

    def run(self, model: str, frame, meta: Any = None) -> Any:
        """``process(frame, meta)`` of ``model``'s analytics on this thread; raises what it raises."""
        obj = self._get(model)
        out = obj.process(frame, meta)
        self._local.timing = dict(getattr(obj, "last_timing", None) or {})
        return out

    @property
    def last_timing(self) -> dict:
        """The ``last_timing`` of the analytics that last ran on this thread (empty if it reports none)."""
        return getattr(self._local, "timing", {})
