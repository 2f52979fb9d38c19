"""Carrying out analytics schedulers' decisions on a real Ray cluster, with wall-clock time.

An analytics scheduler (:class:`aerodaas.schedulers.analytics_base.AnalyticsScheduler`) is a pure policy; this
package is what runs it, one module per concept:

* :mod:`.dispatcher` -- :class:`~.dispatcher.AnalyticsDispatcher`, one per edge device: owns one policy instance,
  the edge executor loop, the poll timer and cloud submission; records every task's terminal state and utility.
* :mod:`.edge_executors` -- :class:`~.edge_executors.EdgeExecutor` s: :class:`~.edge_executors.EmulatedEdgeExecutor`
  holds the model's profile time (``edge_ms`` x a seeded jitter factor); :class:`~.edge_executors.OnnxEdgeExecutor`
  runs a real ONNX detector (:func:`aerodaas.perception.detect.make_detector`: YOLOX-Nano, NanoDet-Plus) on the frame;
  :class:`~.edge_executors.AnalyticsEdgeExecutor` runs an application's analytics.
* :mod:`.cloud_pool` -- :class:`~.cloud_pool.CloudPool`, the edge-side client of the cloud executors (the Ray actor
  :data:`aerodaas.actors.cloud.executor.CloudExecutorActor`), shared by the dispatchers of one process: batched
  transport, replies on the intended schedule, cloud node loss.
* :mod:`.payload` -- :class:`~.payload.FramePayload` (a task's frame) and :func:`~.payload.frame_from_payload`.
* :mod:`.banks` -- the models executors run by name: ONNX detectors (:class:`~.banks.DetectorBank`) or an
  application's analytics (:class:`~.banks.AnalyticsBank`).
* :mod:`.clock` -- :class:`~.clock.Clock`, the policies' millisecond clock, and absolute-time asyncio timers.
* :mod:`.emulation` -- seeded random streams, execution-time :class:`~.emulation.Jitter` and the emulated
  :class:`~.emulation.NetworkModel`.
* :mod:`.stats` -- :class:`~.stats.Samples`, bounded latency samples with percentiles.

The benchmark's host of many emulated edge devices is :class:`aerodaas.bench.edge_host.EdgeHost`.

Reference for the policies, the workload and the utility model: S. Raj, R. Mittal, H. Gupta, Y. Simmhan,
"Adaptive heuristics for scheduling DNN inferencing on edge and cloud for personalized UAV fleets", FGCS 2025
(arXiv 2412.20860).
"""
