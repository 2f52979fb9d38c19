"""Analytics inside an actor: :class:`AnalyticsComponent` (one analytics object, ``process`` per item),
:class:`ScheduledAnalyticsComponent` and :class:`AnalyticsSchedulingService` (frames placed on the edge or the cloud
by the analytics scheduler of a dispatcher actor)."""
from __future__ import annotations

import logging
import time
import traceback
from typing import Any

import numpy as np

from aerodaas.analytics.contract import Emissions, collecting, event_record, schema_name
from aerodaas.perception.track_records import records_of, tracks_prefix
from aerodaas.protocol.messages import DetectionsMsg, FrameMsg, Message, NavigationMsg, Port, ValueMsg, output_message
from aerodaas.protocol.specs import AnalyticsSchedulerSpec
from aerodaas.recording.health import DEFAULT_MAX_FAILURE_FRACTION, ComponentKind, FailureCount, FailureLog

from aerodaas.actors.data.plane import Component, DataPlane
from aerodaas.schedulers.dispatch.banks import AnalyticsBank
from aerodaas.schedulers.dispatch.cloud_pool import CloudPool
from aerodaas.schedulers.dispatch.dispatcher import AnalyticsDispatcher
from aerodaas.schedulers.dispatch.edge_executors import AnalyticsEdgeExecutor
from aerodaas.schedulers.dispatch.emulation import NetworkModel
from aerodaas.schedulers.dispatch.payload import FramePayload


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
        t0 = time.perf_counter()
        try:
            with collecting(self.obj) as em:
                res = self.obj.process_batch([(m.data, m.meta) for _, m in fresh])
        except Exception:  # noqa: BLE001 - find the culprit item by item
            res = None
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
        t0 = time.perf_counter()
        try:
            with collecting(self.obj) as em:
                out = self.obj.process(msg.data, msg.meta)
        except Exception as e:  # noqa: BLE001 - the analytics' own bug: logged, recorded, counted, policy applied
            self._failed(e, msg)
            return None
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
        records = records_of(self.obj)
        if self.recorder is None or records is None:
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
               "process_ms_median": float(np.median(p)), **self.mailbox_stats(),
               "failures": self.failures, "last_failure": self.last_failure, "on_error": self.on_error,
               "health": {**self.health.count.as_dict(), "cid": self.cid},
               "outlets": self.plane.outlet_stats(self.cid), "events": dict(self.events),
               "named_outputs": dict(self.named_counts)}
        extra = getattr(self.obj, "stats", None)
        if callable(extra):
            out.update(extra())
        return out


class ScheduledAnalyticsComponent(AnalyticsComponent):
    """An analytics whose frames the *analytics scheduler* places (the paper's setAnalyticsScheduler): every frame
    delivered to it becomes a task — (drone, this analytics as the model, the frame, arrival now, deadline from its
    QoS) — that :class:`AnalyticsSchedulingService`'s policy runs on the edge (here, on the frame object itself), sends
    to the cloud (as JPEG, with the FrameMeta) or drops with a reason. A result that is done by its deadline is
    recorded and published downstream exactly as an unscheduled analytics' output; a late one earns nothing and is
    only counted. Every task's outcome is recorded on ``/<robot>/<name>/tasks``. The mailbox only hands frames to the
    scheduler (microseconds), so it never drops: dropping is the scheduler's decision, with its reason."""

    def __init__(self, plane: DataPlane, cid: str, name: str, analytics: Any, recorder: Any, epoch_ns: int,
                 service: "AnalyticsSchedulingService") -> None:
        super().__init__(plane, cid, name, analytics, recorder, epoch_ns, buffer=256)
        self.service = service
        self.outcomes: dict[str, int] = {}
        #: executed tasks (done on time or late) per tier, and those whose result was non-empty (e.g. detections)
        self.executed: dict[str, int] = {}
        self.with_output: dict[str, int] = {}

    def batch_limit(self) -> int:
        return 1  # each frame is a task of the analytics scheduler

    def handle(self, port: Port, msg: Message) -> None:
        frame = msg.data
        if not (isinstance(msg, FrameMsg) and isinstance(frame, np.ndarray) and frame.ndim == 3):
            raise TypeError(f"scheduled analytics {self.name!r} takes camera frames ((H, W, 3) uint8 BGR), got "
                            f"{type(frame).__name__}")
        tok = msg.tok
        if tok is not None:
            tok.add()  # held until the task's terminal state (on_task_done)
        try:
            self.service.submit(self, msg)
        except Exception:
            if tok is not None:
                tok.done()
            raise
        return None

    def on_task_done(self, task: Any) -> None:
        """Called by the dispatcher (its loop thread) once per task, in its terminal state: publish an on-time
        result, record the outcome (with the utility and cost the dispatcher computed, and the scheduler's name:
        the recorder tallies these records, :class:`aerodaas.recording.task_tally.TaskTally`), release the
        lock-step hold."""
        msg: Message = task.payload.context
        tok = msg.tok
        try:
            state = task.state.value
            self.outcomes[state] = self.outcomes.get(state, 0) + 1
            if state in ("done_on_time", "done_late"):  # the model ran, on the edge or in the cloud
                tier = task.tier or "edge"
                self.executed[tier] = self.executed.get(tier, 0) + 1
                self.with_output[tier] = self.with_output.get(tier, 0) + bool(task.result)
            robot = msg.robot or task.drone
            if self.recorder is not None:
                t_ns = self.epoch_ns + int(msg.sim_t * 1e9)
                rec = {"task_id": task.task_id, "model": task.model, "state": state, "tier": task.tier,
                       "reason": task.reason, "arrival_ms": task.arrival_ms, "deadline_ms": task.deadline_ms,
                       "start_ms": task.start_ms, "end_ms": task.end_ms, "utility": task.utility,
                       "cost": task.cost, "scheduler": self.service.policy_name}
                self.recorder.json(f"/{robot}/{self.name}/tasks", t_ns, rec, "aerodaas.AnalyticsTask")
            if state != "done_on_time":
                self._no_output(msg)  # the scheduler dropped it, or its result came late: no output recorded
            # the edge executor ran this actor's own object, outside a collector: what it emitted is on the object
            # (a cloud copy's emissions stay in its executor actor and are not recorded)
            emitted = self.obj.take_emissions() if hasattr(self.obj, "take_emissions") else None
            if state == "done_on_time":
                dt_ms = (task.end_ms - task.start_ms) if task.start_ms is not None and task.end_ms is not None else 0.0
                timing = task.notes.get("timing") if task.tier == "edge" else {"inference_ms": dt_ms}
                outs = self._emit(task.result, msg, dt_ms, timing, emitted)
                if outs:
                    self.plane.publish(self.cid, outs, tok)
            elif emitted is not None and (emitted.events or emitted.outputs):
                self._emitted(emitted, msg)
        except Exception as e:  # never lose the hold or the dispatcher's loop over one bad result
            self.errors += 1
            self.plane.report_error(self.cid, e)
        finally:
            if tok is not None:
                tok.done()

    def stats(self) -> dict:
        out = super().stats()
        out["scheduled"] = {"scheduler": self.service.name, "outcomes": dict(self.outcomes),
                            "executed": dict(self.executed), "with_output": dict(self.with_output)}
        if "frames_with_detections" in out:  # the edge copy's own counts miss the frames the cloud served
            out["frames"] = sum(self.executed.values())
            out["frames_with_detections"] = sum(self.with_output.values())
            out["frames_by_tier"] = dict(self.executed)
        return out


class AnalyticsSchedulingService:
    """The edge device's analytics scheduler, inside the edge actor: one :class:`aerodaas.schedulers.dispatch.dispatcher.AnalyticsDispatcher`
    (one policy instance, one edge executor thread, the scheduler's timers) for every scheduled analytics of the
    actor, each analytics being one *model* of the workload. Edge tasks run the actor's own analytics objects on the
    camera's frame (no copy); cloud tasks go to ``CloudExecutor`` actors (tier=cloud) that run copies of the same
    analytics on the JPEG. A cloud executor that dies (its node lost) is handled by the pool: in-flight tasks are
    retried or FAILED, the policy is told when no cloud is left, and the mission goes on.

    ``spec``: the dispatcher actor's :class:`~aerodaas.protocol.specs.AnalyticsSchedulerSpec` (the scheduler's
    class itself, resolved in the driver where an application's own scheduler is registered)."""

    def __init__(self, plane: DataPlane, spec: AnalyticsSchedulerSpec) -> None:
        self.plane = plane
        self.spec = spec
        self.name = spec.name
        #: the policy's own name (its report's ``scheduler``), once started; on every task record
        self.policy_name = spec.name
        self.comps: dict[str, ScheduledAnalyticsComponent] = {}
        self.dispatcher = None
        self.final: dict | None = None

    def add(self, comp: ScheduledAnalyticsComponent) -> None:
        if comp.name in self.comps:
            raise ValueError(f"two scheduled analytics are named {comp.name!r}; give them distinct names")
        self.comps[comp.name] = comp

    def start(self) -> None:
        w = self.spec.workload
        policy = self.spec.policy_class(w)
        self.policy_name = policy.name or self.name
        bank = AnalyticsBank({n: c.obj for n, c in self.comps.items()}, shared=True)
        ex = list(self.spec.executors)
        pool = CloudPool(ex, mode="real", network=NetworkModel.parse(self.spec.network or ["none"],
                                                                     seed=int(self.spec.seed)),
                         jpeg_quality=int(self.spec.jpeg_quality)) if ex else None
        self.dispatcher = AnalyticsDispatcher(policy, AnalyticsEdgeExecutor(bank), pool, edge_id=self.plane.actor_id,
                                              on_result=self._on_result, keep_tasks=False)
        self.dispatcher.start_background()

    def submit(self, comp: ScheduledAnalyticsComponent, msg: Message) -> None:
        self.dispatcher.submit(msg.robot, comp.name, FramePayload(msg.data, msg.meta, msg))

    def _on_result(self, task: Any) -> None:
        self.comps[task.model].on_task_done(task)

    def report(self) -> dict:
        """The dispatcher's report (utility, states, drops by reason, decision latency, cloud losses): final after
        :meth:`finish`, else the run so far."""
        if self.final is not None:
            return self.final
        rep = self.dispatcher.report() if self.dispatcher is not None else {}
        if self.dispatcher is not None and self.dispatcher.cloud is not None:
            rep["cloud"] = self.dispatcher.cloud.report()
        return rep

    def finish(self) -> dict:
        """End the run: tasks still held end with a reason (every task reaches one terminal state); idempotent."""
        if self.final is None and self.dispatcher is not None:
            self.final = self.dispatcher.finish_background()
        return self.final or {}
