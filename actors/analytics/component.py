"""Analytics inside an actor: :class:`AnalyticsComponent` (one analytics object, ``process`` per item). An analytics
whose frames a dispatcher actor's analytics scheduler places is in :mod:`aerodaas.actors.dispatch.scheduling`."""
from __future__ import annotations

import logging
import time
import traceback
from typing import Any

import numpy as np

from aerodaas.analytics.contract import Emissions, collecting, event_record, schema_name
from aerodaas.protocol.messages import DetectionsMsg, Message, NavigationMsg, Port, ValueMsg, output_message
from aerodaas.recording.health import DEFAULT_MAX_FAILURE_FRACTION, ComponentKind, FailureCount, FailureLog

from aerodaas.actors.data.plane import Component, DataPlane


class AnalyticsComponent(Component):
    """Hosts one analytics (IAnalyse / INavigableAnalyse) object: ``setup()`` once, then ``process()`` on every
    delivered item; non-None outputs are recorded and published. An item older than the newest one already
    processed from the same source (possible when two pool threads race) is skipped as stale.

    The analytics' output contract (:mod:`aerodaas.analytics.contract`): a declared ``Output`` is checked and
    recorded with its own schema, then published as a JSON-ready dict; what it sends to a named output
    (:meth:`~aerodaas.analytics.base.Analytics.emit`) is recorded on ``/<robot>/<name>/<output>`` and published
    from the component id ``<cid>:<output>`` (the plan routes each named output from there); its events go to
    ``/<robot>/events`` and are counted per kind (``events`` in :meth:`stats`)."""

    kind = "analytics"

    def __init__(self, plane: DataPlane, cid: str, name: str, analytics: Any, recorder: Any, epoch_ns: int,
                 buffer: int = 1) -> None:
        super().__init__(plane, cid, buffer)
        self.name = name
        self.obj = analytics
        self.obj.setup()
        self.recorder = recorder
        self.epoch_ns = epoch_ns
        self.processed = 0
        self.outputs = 0
        self.stale = 0
        self.latest: Any = None
        self.proc_ms: list[float] = []
        #: CPU seconds in the analytics object's own ``process`` / ``process_batch`` calls, on the thread that ran
        #: each (``time.thread_time``): the user's part of the hosting actor's CPU
        self.process_cpu_s = 0.0
        self._newest: dict[tuple, float] = {}
        self.failures = 0  # items whose process() raised
        self.batched = 0  # items processed in a process_batch call of more than one item
        self.last_failure: str | None = None
        self.on_error = getattr(analytics, "on_error", "continue")  # continue | abort (checked before Ray)
        self.aborted = False
        self.output_model = getattr(analytics, "Output", None)  # None: free-form output
        self.named_outputs = dict(getattr(analytics, "named_outputs", None) or {})
        self.events: dict[str, int] = {}  # kind -> events emitted
        self.named_counts: dict[str, int] = {k: 0 for k in self.named_outputs}
        #: its items and failures (every one counted; the first ones and then summaries recorded as events)
        self.health = FailureLog(FailureCount(ComponentKind.ANALYTICS, None, name, limit=float(
            getattr(analytics, "max_failure_fraction", DEFAULT_MAX_FAILURE_FRACTION))))
        self._failed_at: tuple[str, float] | None = None  # robot and vehicle time (s) of the last failure
        if recorder is not None:  # its outputs are accounted against its inputs (aerodaas.recording.accounting)
            recorder.declare_analytics(cid, name)

    def offer(self, port: Port, msg: Message) -> bool:
        """:meth:`Component.offer`; an item its full mailbox drops (load shed) is counted as taken without output."""
        ok = super().offer(port, msg)
        if not ok:
            self._no_output(msg)
        return ok

    def _no_output(self, msg: Message) -> None:
        """An item taken without recording an output: not a loss of the output channel (recording accounting)."""
        if self.recorder is not None:
            self.recorder.count_no_output(self.cid, self.name, msg.robot)

    def handle(self, port: Port, msg: Message) -> list[Message] | None:
        if self._stale(msg):
            return None
        return self._process_one(msg)

    def batch_limit(self) -> int:
        """The analytics' ``max_batch`` (> 1 only for a model that takes several frames per inference call)."""
        try:
            return max(1, int(getattr(self.obj, "max_batch", 1) or 1))
        except (TypeError, ValueError):
            return 1

    def handle_batch(self, items: list[tuple[Port, Message]]) -> list[list[Message] | None]:
        """Several waiting items (e.g. frames of several drones for one detector) in one ``process_batch`` call;
        stale items are skipped as in :meth:`handle`. If the batch raises, each item is processed alone, so the
        failing one is found and counted like any other failure."""
        fresh = [(p, m) for p, m in items if not self._stale(m)]
        out: list = [None] * len(items)
        if not fresh:
            return out
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            with collecting(self.obj) as em:
                res = self.obj.process_batch([(m.data, m.meta) for _, m in fresh])
        except Exception:  # noqa: BLE001 - find the culprit item by item
            res = None
        self.process_cpu_s += time.thread_time() - c0
        dt_ms = (time.perf_counter() - t0) * 1e3 / len(fresh)
        index = {id(e): i for i, (_, e) in enumerate(items)}
        for j, (p, e) in enumerate(fresh):
            if res is None:
                out[index[id(e)]] = self._process_one(e)
            else:
                self.batched += 1
                out[index[id(e)]] = self._emit(res[j], e, dt_ms, getattr(self.obj, "last_timing", None),
                                               self._of_item(em, j))
        return out

    @staticmethod
    def _of_item(em: Emissions, j: int) -> Emissions:
        """What was emitted while item ``j`` of a batch was processed."""
        return Emissions([x for x in em.events if x[0] == j], [x for x in em.outputs if x[0] == j])

    def _stale(self, msg: Message) -> bool:
        meta = msg.meta
        if meta is not None:
            key = (meta.robot_id, meta.sensor_id)
            if meta.capture_time < self._newest.get(key, -1.0):
                self.stale += 1
                self._no_output(msg)
                return True
            self._newest[key] = meta.capture_time
        return False

    def _process_one(self, msg: Message) -> list[Message] | None:
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            with collecting(self.obj) as em:
                out = self.obj.process(msg.data, msg.meta)
        except Exception as e:  # noqa: BLE001 - the analytics' own bug: logged, recorded, counted, policy applied
            self.process_cpu_s += time.thread_time() - c0
            self._failed(e, msg)
            return None
        self.process_cpu_s += time.thread_time() - c0
        dt_ms = (time.perf_counter() - t0) * 1e3
        return self._emit(out, msg, dt_ms, getattr(self.obj, "last_timing", None), em)

    def _failed(self, e: Exception, msg: Message) -> None:
        """An exception in ``process``: logged with its traceback (the first 5, then every 100th), counted in the
        run's summary, recorded as an ``analytics_error`` event of the robot (the first ones, then
        ``analytics_error_summary`` events: :class:`~aerodaas.recording.health.FailureLog`); ``on_error ==
        "abort"`` ends every mission of the run as failed (once)."""
        self.failures += 1
        self._no_output(msg)
        tb = traceback.format_exc()
        self.last_failure = f"{type(e).__name__}: {e}"
        if self.failures <= 5 or self.failures % 100 == 0:
            logging.getLogger("aerodaas.analytics.core").error("analytics %r failed on item %d (%d failures so far):\n%s",
                                                          self.name, self.processed + self.failures, self.failures, tb)
        self.health.attempt()
        self._failed_at = (msg.robot, msg.sim_t)
        ev = self.health.failed(msg.sim_t, self.last_failure)
        if ev is not None and ev["event"] == ComponentKind.ANALYTICS.event:
            ev["traceback"] = tb
        self._record_failures(ev)
        if self.on_error == "abort" and not self.aborted:
            self.aborted = True
            abort = getattr(self, "abort", None)
            if callable(abort):
                abort(f"analytics {self.name!r} raised {self.last_failure} (on_error=abort)")

    def _record_failures(self, ev: dict | None) -> None:
        """Record failure event ``ev`` (None: nothing now) on the events of the robot of the last failure."""
        if ev is None or self.recorder is None or self._failed_at is None:
            return
        robot, t = self._failed_at
        self.recorder.json(f"/{robot}/events", self.epoch_ns + int(t * 1e9),
                           {"robot": robot, "t": t, **ev, "on_error": self.on_error}, "aerodaas.MissionEvent")

    def finish_failures(self) -> None:
        """The run is over: the failures no event carried yet, as one ``analytics_error_summary`` event (at the
        vehicle time of the last failure)."""
        if self._failed_at is not None:
            self._record_failures(self.health.summary(self._failed_at[1]))

    def _emit(self, out: Any, msg: Message, dt_ms: float, timing: dict | None,
              emitted: Emissions | None = None) -> list[Message] | None:
        """Count one processed item that took ``dt_ms`` (ms), record and publish what it ``emitted`` (events, named
        outputs) and, for a non-None output, record it and return the message to publish; ``timing["inference_ms"]``
        (if given) splits ``dt_ms`` into inference and post-processing in the latency trace. An output that is not
        the declared ``Output`` is a failure of the item (:meth:`_failed`)."""
        meta = msg.meta
        if out is not None and self.output_model is not None:
            try:
                out = self._typed(out)
            except Exception as e:  # noqa: BLE001 - the analytics broke its declared contract: an item failure
                self._failed(e, msg)
                return None
        self.proc_ms.append(dt_ms)
        self.processed += 1
        self.health.attempt()
        self.plane.mark_processed()
        self._record_tracks(msg)
        if emitted is not None and (emitted.events or emitted.outputs):
            self._emitted(emitted, msg)
        if out is None:
            self._no_output(msg)
            return None
        self.outputs += 1
        self.latest = out
        trace = dict(msg.trace)
        if timing and "inference_ms" in timing:
            trace["inference_ms"] = trace.get("inference_ms", 0.0) + timing["inference_ms"]
            trace["post_ms"] = trace.get("post_ms", 0.0) + dt_ms - timing["inference_ms"]
        else:
            trace["post_ms"] = trace.get("post_ms", 0.0) + dt_ms
        res = output_message(out, msg, trace)
        robot = msg.robot
        if self.recorder is not None:
            t_ns = self.epoch_ns + int(msg.sim_t * 1e9)
            if self.output_model is not None:
                self.recorder.json(f"/{robot}/{self.name}", t_ns, out, schema_name(self.output_model))
            elif isinstance(res, DetectionsMsg):
                size = (meta.intrinsics.width, meta.intrinsics.height) if meta else None
                self.recorder.detections(f"/{robot}/{self.name}/detections", t_ns, out, size)
            elif isinstance(res, NavigationMsg):
                self.recorder.json(f"/{robot}/{self.name}/navigation", t_ns, out.model_dump(mode="json"),
                                   "aerodaas.AeroNavigation")
            elif isinstance(out, dict):
                self.recorder.json(f"/{robot}/{self.name}", t_ns, out, "aerodaas.AnalyticsOutput")
            else:
                self._no_output(msg)  # an output of another kind is published, not recorded
        return [res]

    def _typed(self, out: Any) -> dict:
        """``out`` as the declared ``Output`` model's JSON-ready dict. Raises TypeError naming the analytics, the
        declared model and what was returned; pydantic's ValidationError for a dict that is not the model."""
        model = self.output_model
        if isinstance(out, model):
            return out.model_dump(mode="json")
        if isinstance(out, dict):
            return model.model_validate(out).model_dump(mode="json")
        raise TypeError(f"analytics {self.name!r} returned a {type(out).__name__}, but it declares Output = "
                        f"{model.__name__} (return a {model.__name__}, a dict of its fields, or None)")

    def _emitted(self, em: Emissions, msg: Message) -> None:
        """Record ``em``'s events on ``/<robot>/events`` and its named outputs on ``/<robot>/<name>/<output>``, and
        publish each named output from ``<cid>:<output>``, all with ``msg``'s robot and time."""
        robot, t_ns = msg.robot, self.epoch_ns + int(msg.sim_t * 1e9)
        for _, ev in em.events:
            self.events[ev.kind] = self.events.get(ev.kind, 0) + 1
            if self.recorder is not None:
                self.recorder.json(f"/{robot}/events", t_ns, event_record(robot, msg.sim_t, self.name, ev),
                                   "aerodaas.MissionEvent")
        for _, no in em.outputs:
            self.named_counts[no.output] = self.named_counts.get(no.output, 0) + 1
            data = no.message.model_dump(mode="json")
            if self.recorder is not None:
                self.recorder.json(f"/{robot}/{self.name}/{no.output}", t_ns, data, schema_name(type(no.message)))
            self.plane.publish(f"{self.cid}:{no.output}", [ValueMsg(robot=robot, sim_t=msg.sim_t, data=data,
                                                                    trace=dict(msg.trace))], msg.tok, inline=False)

    def _record_tracks(self, msg: Message) -> None:
        """A tracking analytics' tracks of this frame (its ``track_records``, :mod:`aerodaas.perception.track_records`)
        go to the recorder under ``/<robot>/<name>/tracks``, whatever the analytics' own output was."""
        if self.recorder is None or getattr(self.obj, "track_records", None) is None:
            return
        # an analytics that does not track (the fleet benchmark's exposure, colocated in a drone actor) keeps the
        # tracker, geo-location and colours out of its process; a tracking one's module imported them already
        from aerodaas.perception.track_records import records_of, tracks_prefix  # lazy: tracking analytics only

        records = records_of(self.obj)
        if records is None:
            return
        rows = records.take(msg.meta)
        if rows is None:
            return

        meta = msg.meta
        size = (meta.intrinsics.width, meta.intrinsics.height) if meta else None
        self.recorder.tracks(tracks_prefix(msg.robot, self.name), self.epoch_ns + int(msg.sim_t * 1e9), msg.robot,
                             rows, size)

    def get_latest(self) -> Any:
        return self.latest

    def stats(self) -> dict:
        p = np.array(self.proc_ms or [0.0])
        out = {"name": self.name, "processed": self.processed, "outputs": self.outputs, "stale": self.stale,
               "batched": self.batched,
               "process_ms_median": float(np.median(p)), "process_cpu_s": round(self.process_cpu_s, 6),
               **self.mailbox_stats(),
               "failures": self.failures, "last_failure": self.last_failure, "on_error": self.on_error,
               "health": {**self.health.count.as_dict(), "cid": self.cid},
               "outlets": self.plane.outlet_stats(self.cid), "events": dict(self.events),
               "named_outputs": dict(self.named_counts)}
        extra = getattr(self.obj, "stats", None)
        if callable(extra):
            out.update(extra())
        return out
