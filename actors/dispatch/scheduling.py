"""Analytics whose frames the analytics scheduler of a dispatcher actor places on the edge or the cloud:
:class:`ScheduledAnalyticsComponent` (one analytics, every frame a task) and :class:`AnalyticsSchedulingService`
(the edge device's one :class:`~aerodaas.schedulers.dispatch.dispatcher.AnalyticsDispatcher` for all of them)."""
from __future__ import annotations

from typing import Any

import numpy as np

from aerodaas.protocol.messages import FrameMsg, Message, Port
from aerodaas.protocol.specs import AnalyticsSchedulerSpec

from aerodaas.actors.analytics.component import AnalyticsComponent
from aerodaas.actors.data.plane import DataPlane
from aerodaas.schedulers.dispatch.banks import AnalyticsBank
from aerodaas.schedulers.dispatch.cloud_pool import CloudPool
from aerodaas.schedulers.dispatch.dispatcher import AnalyticsDispatcher
from aerodaas.schedulers.dispatch.edge_executors import AnalyticsEdgeExecutor
from aerodaas.schedulers.dispatch.emulation import NetworkModel
from aerodaas.schedulers.dispatch.payload import FramePayload


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
