"""Edge executors: run one analytics task at a time on the edge device's accelerator, for the
:class:`~aerodaas.schedulers.dispatch.dispatcher.AnalyticsDispatcher`.

:class:`EmulatedEdgeExecutor` holds the model's profile time (``edge_ms`` x a seeded :class:`Jitter` factor);
:class:`OnnxEdgeExecutor` runs a real ONNX detector (:func:`aerodaas.perception.detect.make_detector`: YOLOX-Nano,
NanoDet-Plus) on the frame; :class:`AnalyticsEdgeExecutor` runs an application's analytics on it.
"""
from __future__ import annotations

import abc
import asyncio
import concurrent.futures
from typing import Any, Mapping

from aerodaas.schedulers.analytics_base import AnalyticsTask, Workload

from aerodaas.schedulers.dispatch.banks import AnalyticsBank, DetectorBank
from aerodaas.schedulers.dispatch.clock import set_result_if_pending
from aerodaas.schedulers.dispatch.emulation import Jitter, seeded_rng
from aerodaas.schedulers.dispatch.payload import frame_from_payload

__all__ = ["EdgeExecutor", "EmulatedEdgeExecutor", "OnnxEdgeExecutor", "AnalyticsEdgeExecutor"]


class EdgeExecutor(abc.ABC):
    """Runs one task on the edge accelerator (the dispatcher runs one at a time).

    :meth:`run` is a coroutine on the dispatcher's loop; it returns ``(result, intended_ms)``: the model's output
    (or None) and, for emulated executors, the hold time it aimed for (None for real ones), which the dispatcher
    compares with the measured time to report the emulation's timing error. It raises on failure (the task ends
    FAILED with the error as reason)."""

    @abc.abstractmethod
    async def run(self, task: AnalyticsTask, workload: Workload, edge_id: str) -> tuple[Any, float | None]:
        ...

    def describe(self) -> dict:
        return {"kind": type(self).__name__}


class EmulatedEdgeExecutor(EdgeExecutor):
    """Holds the model's profile time on the edge: ``edge_ms`` x ``jitter.factor`` (seeded by ``(seed, edge_id,
    task_id)``), as an asyncio timer aimed at an absolute loop time (so loop delays do not accumulate)."""

    def __init__(self, jitter: Jitter = Jitter(), seed: int = 0) -> None:
        self.jitter = jitter
        self.seed = int(seed)

    async def run(self, task: AnalyticsTask, workload: Workload, edge_id: str) -> tuple[Any, float | None]:
        loop = asyncio.get_running_loop()
        start = loop.time()
        hold = workload[task.model].edge_ms * self.jitter.factor(seeded_rng(self.seed, "edge", edge_id, task.task_id))
        fut = loop.create_future()
        handle = loop.call_at(start + hold / 1000.0, set_result_if_pending, fut, None)
        try:
            await fut
        finally:
            handle.cancel()
        return None, hold

    def describe(self) -> dict:
        return {"kind": "emulated", "jitter": str(self.jitter), "seed": self.seed}


class OnnxEdgeExecutor(EdgeExecutor):
    """Runs a real ONNX detector on the task's frame on one worker thread (the edge's one accelerator).

    ``detector_for``: the detector name for every workload model (``"yolox_nano"``, ``"nanodet_plus_m_416"``) or a
    mapping model -> name (the workload's models are stand-ins: any model may be mapped to either detector).
    ``detector_kwargs`` go to :func:`aerodaas.perception.detect.make_detector` (``model_path``, ``score_threshold``, ...).
    The payload is an ndarray, an ObjectRef to one (same node: zero-copy), or JPEG bytes. The result is the list of
    :class:`~aerodaas.model.types.Detection`.
    """

    def __init__(self, detector_for: Mapping[str, str] | str = "yolox_nano",
                 detector_kwargs: Mapping[str, Any] | None = None) -> None:
        self.bank = DetectorBank(detector_for, detector_kwargs)
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="edge-onnx")

    async def run(self, task: AnalyticsTask, workload: Workload, edge_id: str) -> tuple[Any, float | None]:
        payload = task.payload
        loop = asyncio.get_running_loop()
        dets = await loop.run_in_executor(self._pool, lambda: self.bank.detect(task.model, frame_from_payload(payload)))
        return dets, None

    def describe(self) -> dict:
        return {"kind": "onnx", "detectors": self.bank.detector_for}


class AnalyticsEdgeExecutor(EdgeExecutor):
    """Runs an application's analytics on the edge, one task at a time on one worker thread (the edge's one
    accelerator): ``bank.run(task.model, frame, meta)`` for a :class:`FramePayload`. The result is the analytics'
    output (e.g. a list of :class:`~aerodaas.model.types.Detection`); ``last_timing`` of the analytics goes to
    ``task.notes["timing"]``."""

    def __init__(self, bank: AnalyticsBank) -> None:
        self.bank = bank
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="edge-analytics")

    async def run(self, task: AnalyticsTask, workload: Workload, edge_id: str) -> tuple[Any, float | None]:
        payload = task.payload
        meta = getattr(payload, "meta", None)

        def work():
            out = self.bank.run(task.model, frame_from_payload(payload), meta)
            task.notes["timing"] = self.bank.last_timing
            return out

        return await asyncio.get_running_loop().run_in_executor(self._pool, work), None

    def describe(self) -> dict:
        return {"kind": "analytics", "models": sorted(self.bank.analytics)}
