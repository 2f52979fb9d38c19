"""The analytics-scheduler contract: per-frame placement of DNN tasks on the edge or the cloud.

An analytics scheduler (the paper's ``setAnalyticsScheduler`` plug-in) receives *tasks* — one per (frame, model): the
drone, the model, the frame (opaque ``payload``: an ObjectRef or JPEG bytes), the arrival time and an absolute deadline
— and decides for each: run it on the edge queue, send it to the cloud, or drop it with a reason. It is a pure policy
object: it owns its queues but never executes, sleeps or talks to Ray. A *dispatcher* drives it (see
:mod:`aerodaas.schedulers.dispatch.dispatcher`): it calls :meth:`AnalyticsScheduler.submit` when a task arrives,
:meth:`AnalyticsScheduler.next_edge_task` whenever the edge executor is free, :meth:`AnalyticsScheduler.poll` at
:meth:`AnalyticsScheduler.next_poll_ms` (just-in-time cloud releases, windows, cool-downs), and reports completions; it
carries out the returned :class:`Decision` s. All methods are called under one lock, from one thread at a time. All
times are **milliseconds** on the dispatcher's monotonic clock (``now_ms``), as in the workload's profile.

Terminal states (:class:`TaskState`): every task ends in exactly one of done on time, done late, dropped for
time, dropped for cost, expired at the edge, failed — counted, never lost. Utility (:func:`task_utility`),
per the Ocularone workload: a task completed by its deadline earns its model's ``benefit``; the ``cost`` of the
tier it ran on is charged whether or not it met the deadline (also when it failed there); dropped and expired
tasks count zero.

Reference for the DEMS family and its baselines: S. Raj, R. Mittal, H. Gupta, Y. Simmhan, "Adaptive heuristics
for scheduling DNN inferencing on edge and cloud for personalized UAV fleets", FGCS 2025
(doi:10.1016/j.future.2025.107874; arXiv 2412.20860). The workload is ``ocularone_lambda.json``.
"""
from __future__ import annotations

import abc
import json
import math
import os
from collections import Counter
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Callable, ClassVar, Iterable, Mapping

from aerodaas.plugins import registry

__all__ = ["ModelProfile", "Workload", "TaskState", "AnalyticsTask", "Decision", "AnalyticsScheduler",
           "task_utility", "register_analytics_scheduler", "analytics_scheduler_names",
           "analytics_scheduler_class", "make_analytics_scheduler",
           "TERMINAL_STATES", "admit_by_time", "filter_options", "CloudCounters"]


# --------------------------------------------------------------------------------------------- workload
@dataclass(frozen=True)
class ModelProfile:
    """One DNN model of the workload. Times in ms: ``edge_ms`` expected execution on the edge accelerator,
    ``cloud_ms`` expected round trip on the cloud function; ``deadline_ms`` relative deadline from arrival
    under the chosen load. Utilities: ``benefit`` earned on time; ``edge_cost`` / ``cloud_cost`` charged when
    run there."""

    name: str
    edge_ms: float
    cloud_ms: float
    benefit: float
    edge_cost: float
    cloud_cost: float
    deadline_ms: float

    @property
    def edge_utility(self) -> float:
        """benefit - edge_cost: utility of an on-time edge execution."""
        return self.benefit - self.edge_cost

    @property
    def cloud_utility(self) -> float:
        """benefit - cloud_cost: utility of an on-time cloud execution (may be negative)."""
        return self.benefit - self.cloud_cost


@dataclass(frozen=True)
class Workload:
    """The models active under one load (``LIGHT``/``MEDIUM``/``HEAVY`` in the Ocularone workload), by name."""

    load: str
    models: Mapping[str, ModelProfile]

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], load: str) -> "Workload":
        """Build from the parsed workload JSON (``models`` with edge_ms, cloud_ms, benefit, edge_cost, cloud_cost;
        ``loads`` mapping a load to {model: deadline_ms}). Raises ValueError naming an unknown load or model, or
        a missing/non-positive field."""
        loads = data.get("loads") or {}
        if load not in loads:
            raise ValueError(f"load: unknown load {load!r}; the workload has {sorted(loads)}")
        models = {}
        for name, deadline in loads[load].items():
            m = (data.get("models") or {}).get(name)
            if m is None:
                raise ValueError(f"loads.{load}.{name}: no such model in 'models'")
            for k in ("edge_ms", "cloud_ms", "benefit", "edge_cost", "cloud_cost"):
                if not isinstance(m.get(k), (int, float)) or m[k] < 0:
                    raise ValueError(f"models.{name}.{k}: must be a number >= 0, got {m.get(k)!r}")
            if not isinstance(deadline, (int, float)) or deadline <= 0:
                raise ValueError(f"loads.{load}.{name}: deadline_ms must be > 0, got {deadline!r}")
            models[name] = ModelProfile(name, float(m["edge_ms"]), float(m["cloud_ms"]), float(m["benefit"]),
                                        float(m["edge_cost"]), float(m["cloud_cost"]), float(deadline))
        return cls(load, models)

    @classmethod
    def from_file(cls, path: str | os.PathLike, load: str) -> "Workload":
        """Read a workload JSON file (e.g. ``$AERODAAS_DATA_DIR/workloads/ocularone_lambda.json``)."""
        with open(path) as f:
            return cls.from_dict(json.load(f), load)

    def __getitem__(self, model: str) -> ModelProfile:
        try:
            return self.models[model]
        except KeyError:
            raise KeyError(f"model {model!r} is not in the {self.load} workload ({sorted(self.models)})") from None

    @property
    def min_edge_ms(self) -> float:
        """Shortest edge time of any model (DEMS's work-stealing slack threshold)."""
        return min(m.edge_ms for m in self.models.values())


# --------------------------------------------------------------------------------------------- tasks
class TaskState(str, Enum):
    """Where a task is. PENDING is the only non-terminal state."""

    PENDING = "pending"
    DONE_ON_TIME = "done_on_time"
    DONE_LATE = "done_late"
    DROPPED_TIME = "dropped_time"
    DROPPED_COST = "dropped_cost"
    EXPIRED_EDGE = "expired_edge"
    FAILED = "failed"


TERMINAL_STATES = tuple(s for s in TaskState if s is not TaskState.PENDING)
#: terminal states of a task whose model ran (only these carry a latency that says something about the tier)
EXECUTED_STATES = (TaskState.DONE_ON_TIME, TaskState.DONE_LATE)


@dataclass(eq=False)
class AnalyticsTask:
    """One inference task: ``model`` on one frame of ``drone``. ``arrival_ms``/``deadline_ms`` are absolute times
    on the dispatcher's clock (ms). ``payload`` is the frame (opaque to schedulers). The dispatcher fills
    ``tier`` (where it ran: "edge"/"cloud"), ``start_ms``/``end_ms``, ``state`` and ``reason``, and with the
    terminal state ``utility`` (:func:`task_utility`) and ``cost`` (the edge or cloud cost charged for it, 0 when
    none was: a dropped task), in the workload's units; schedulers may keep private notes in ``notes``."""

    task_id: int
    drone: str
    model: str
    arrival_ms: float
    deadline_ms: float
    payload: Any = None
    tier: str | None = None
    state: TaskState = TaskState.PENDING
    reason: str = ""
    start_ms: float | None = None
    end_ms: float | None = None
    result: Any = None
    notes: dict = field(default_factory=dict)
    utility: float | None = None
    cost: float = 0.0

    def slack_ms(self, now_ms: float, exec_ms: float) -> float:
        """Time to spare if ``exec_ms`` of work started now: deadline - now - exec_ms (negative = would miss)."""
        return self.deadline_ms - now_ms - exec_ms

    def __repr__(self) -> str:
        return (f"AnalyticsTask(#{self.task_id} {self.model}@{self.drone} arr={self.arrival_ms:.0f} "
                f"dl={self.deadline_ms:.0f} {self.state.value}{'/' + self.tier if self.tier else ''})")


@dataclass
class Decision:
    """What the dispatcher must do now with ``task``: ``kind`` ``"cloud"`` (send it to a cloud executor) or
    ``"drop"`` (terminal: ``state`` is DROPPED_TIME, DROPPED_COST or EXPIRED_EDGE). ``reason`` is recorded."""

    kind: str
    task: AnalyticsTask
    reason: str
    state: TaskState | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("cloud", "drop"):
            raise ValueError(f"Decision.kind must be 'cloud' or 'drop', got {self.kind!r}")
        if self.kind == "drop" and self.state not in (TaskState.DROPPED_TIME, TaskState.DROPPED_COST,
                                                      TaskState.EXPIRED_EDGE):
            raise ValueError(f"a drop Decision needs state DROPPED_TIME, DROPPED_COST or EXPIRED_EDGE, got {self.state}")

    @classmethod
    def cloud(cls, task: AnalyticsTask, reason: str) -> "Decision":
        return cls("cloud", task, reason)

    @classmethod
    def drop(cls, task: AnalyticsTask, state: TaskState, reason: str) -> "Decision":
        return cls("drop", task, reason, state)


def task_utility(task: AnalyticsTask, profile: ModelProfile) -> float:
    """Utility of a terminal task: benefit if done on time, minus the cost of the tier it ran on (charged for
    done-late and failed tasks too); 0 for dropped/expired tasks. Raises ValueError for a PENDING task."""
    if task.state is TaskState.PENDING:
        raise ValueError(f"task #{task.task_id} is still pending; utility is defined for terminal tasks only")
    if task.state in (TaskState.DROPPED_TIME, TaskState.DROPPED_COST, TaskState.EXPIRED_EDGE) or task.tier is None:
        return 0.0
    cost = profile.edge_cost if task.tier == "edge" else profile.cloud_cost
    return (profile.benefit if task.state is TaskState.DONE_ON_TIME else 0.0) - cost


# --------------------------------------------------------------------------------------------- the contract
class AnalyticsScheduler(abc.ABC):
    """Base class of analytics schedulers. Subclasses set :attr:`name` (the name used in the CLI, the benchmark
    JSON and ``environment.json``) and implement :meth:`submit` and :meth:`_pop_edge`.

    The edge runs one task at a time (one accelerator). The base class keeps :attr:`edge_running` and
    :attr:`edge_busy_until_ms` (expected end of the running task, from its profile) for policies that need the
    edge backlog. ``cloud_available`` is False while no cloud executor is reachable (e.g. a cloud node died);
    policies must then not return cloud decisions (the base :meth:`_cloud_or_drop` handles this).
    """

    name: ClassVar[str] = ""
    #: plug-in declaration (aerodaas.plugins.registry): registered under :attr:`name`
    plugin_kind: ClassVar[str] = "analytics_scheduler"
    consumes: ClassVar[tuple] = ("analytics_task",)
    produces: ClassVar[tuple] = ("placement_decision",)
    #: whether this policy ever uses the cloud (False for the edge-only baselines)
    uses_cloud: ClassVar[bool] = True
    #: keyword options the constructor accepts (e.g. ``estimator``, ``eviction_scan``); see :func:`filter_options`
    options: ClassVar[tuple[str, ...]] = ()

    def __init__(self, workload: Workload) -> None:
        self.w = workload
        self.edge_running: AnalyticsTask | None = None
        self.edge_busy_until_ms: float = 0.0
        self.cloud_available = True
        #: behaviour counters a policy keeps for the benchmark (steals tried/passed/rejected by reason, JIT
        #: releases, evictions, ...): names are policy-specific, values are event counts
        self.counters: Counter = Counter()

    # -- arrivals
    @abc.abstractmethod
    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        """A new task arrived. Queue it for the edge, hold it, or return decisions (cloud now / drop)."""

    # -- the edge executor is free
    def next_edge_task(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        """The edge is free: return the task to run now (or None to stay idle) and any decisions taken on the
        way (e.g. queued tasks that expired). Marks the returned task as running. A policy may return None while
        it still holds tasks (none fits now, e.g. DEMS's work-stealing candidates): the dispatcher calls this again
        after every later event (submit, poll, completion) while the edge stays free."""
        task, decisions = self._pop_edge(now_ms)
        if task is not None:
            self.edge_running = task
            self.edge_busy_until_ms = now_ms + self.w[task.model].edge_ms
        return task, decisions

    @abc.abstractmethod
    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        """Choose the next edge task (policy-specific). Tasks it gives up on go into the returned decisions."""

    def on_edge_done(self, task: AnalyticsTask, now_ms: float, exec_ms: float) -> list[Decision]:
        """The edge finished ``task`` after ``exec_ms`` of execution. Policies that count outcomes (GEMS) read
        ``task.state`` if the dispatcher already set it (DONE_ON_TIME / DONE_LATE / FAILED), else ``now_ms <=
        deadline``."""
        if self.edge_running is task:
            self.edge_running = None
            self.edge_busy_until_ms = now_ms
        return []

    # -- timers
    def poll(self, now_ms: float) -> list[Decision]:
        """Timer callback (just-in-time releases, windows); called at or after :meth:`next_poll_ms`."""
        return []

    def next_poll_ms(self) -> float | None:
        """When :meth:`poll` must next be called (absolute ms), or None when nothing is timed."""
        return None

    # -- the cloud
    def cloud_admit(self, task: AnalyticsTask, now_ms: float) -> bool:
        """The cloud executor's re-check right before it runs ``task``: by default, can it still finish in time
        with the task's cloud estimate — ``task.notes["cloud_ms"]`` if the policy fixed one when it held the task
        for the cloud (as the reference does), else :meth:`cloud_estimate_ms`? On False the dispatcher drops the
        task (DROPPED_TIME) and reports it through :meth:`on_cloud_done`.

        Must be a pure, monotone query (no side effects, False stays False for later ``now_ms``): the dispatcher
        bisects over ``now_ms`` with about a dozen calls per task to turn it into an admit-by time."""
        return now_ms + task.notes.get("cloud_ms", self.cloud_estimate_ms(task.model)) <= task.deadline_ms

    def cloud_estimate_ms(self, model: str) -> float:
        """Expected cloud round trip for ``model`` in ms (the profile; adaptive policies override)."""
        return self.w[model].cloud_ms

    def on_cloud_done(self, task: AnalyticsTask, now_ms: float, latency_ms: float) -> list[Decision]:
        """A task this policy decided to send to the cloud has ended, once per task: it came back after
        ``latency_ms`` (send to reply, network included), or was refused by the cloud re-check (before sending,
        ``latency_ms`` = 0, or at the executor), or failed, or the cloud was unavailable. ``task.state`` is already
        terminal: only in :data:`EXECUTED_STATES` is ``latency_ms`` a cloud round trip; a task refused (DROPPED_TIME)
        or FAILED never ran, and its reply time says nothing about the cloud's latency."""
        return []

    def on_cloud_availability(self, available: bool, now_ms: float) -> list[Decision]:
        """The cloud became (un)available. Policies holding tasks for the cloud must re-place them (edge or drop).
        The base class only records the flag."""
        self.cloud_available = available
        return []

    # -- end of run
    @abc.abstractmethod
    def held_tasks(self) -> list[AnalyticsTask]:
        """Every task the scheduler still holds (edge queue, tentative queues, candidates), for the final
        accounting: the dispatcher drops them as DROPPED_TIME ("run ended") when the run stops."""

    # -- helpers shared by policies
    def _cloud_or_drop(self, task: AnalyticsTask, now_ms: float, reason: str) -> Decision:
        """Send to the cloud if that is worth it (benefit - cloud cost > 0) and in time (now + cloud time <=
        deadline) and the cloud is available; otherwise the drop decision with the reason that applies."""
        p = self.w[task.model]
        if p.cloud_utility <= 0:
            return Decision.drop(task, TaskState.DROPPED_COST, f"{reason}; cloud utility {p.cloud_utility:g} <= 0")
        if not self.cloud_available:
            return Decision.drop(task, TaskState.DROPPED_TIME, f"{reason}; cloud unavailable")
        if now_ms + self.cloud_estimate_ms(task.model) > task.deadline_ms:
            return Decision.drop(task, TaskState.DROPPED_TIME, f"{reason}; cloud time {self.cloud_estimate_ms(task.model):.0f} ms "
                                 f"exceeds the {task.deadline_ms - now_ms:.0f} ms left")
        return Decision.cloud(task, reason)


# --------------------------------------------------------------------------------------------- run counters
class CloudCounters:
    """What a driver (the dispatcher, the policy harness) counts about a policy's cloud use: tasks sent, the
    in-flight count over time (peak and time-weighted mean between the first send and the last reply), and cloud
    tasks that came back late — all of them, and those the policy had *held* before sending (sent at least 1 ms
    after arrival: a just-in-time release, a late eviction), which paid the cloud cost for no benefit."""

    def __init__(self) -> None:
        self.sent = self.in_flight = self.peak = self.late = self.late_held = 0
        self._area = 0.0
        self._first: float | None = None
        self._last: float | None = None

    def _advance(self, now_ms: float) -> None:
        if self._last is not None:
            self._area += self.in_flight * max(0.0, now_ms - self._last)
        if self._first is None:
            self._first = now_ms
        self._last = now_ms

    def on_send(self, now_ms: float) -> None:
        self._advance(now_ms)
        self.sent += 1
        self.in_flight += 1
        self.peak = max(self.peak, self.in_flight)

    def on_end(self, task: AnalyticsTask, now_ms: float) -> None:
        """``task`` (sent earlier, terminal now) came back or failed."""
        self._advance(now_ms)
        self.in_flight = max(0, self.in_flight - 1)
        if task.state is TaskState.DONE_LATE:
            self.late += 1
            self.late_held += int(task.start_ms is not None and task.start_ms - task.arrival_ms >= 1.0)

    def summary(self) -> dict:
        span = (self._last - self._first) if self._first is not None and self._last is not None else 0.0
        return {"cloud_sent": self.sent, "cloud_peak_concurrency": self.peak,
                "cloud_mean_concurrency": self._area / span if span > 0 else 0.0,
                "cloud_done_late": self.late, "cloud_done_late_after_hold": self.late_held}


# --------------------------------------------------------------------------------------------- registry


def admit_by_time(admits: Callable[[float], bool], now_ms: float, deadline_ms: float) -> float | None:
    """The latest time (ms, 1 ms resolution) at which the cloud re-check ``admits(t)`` still holds, by bisection
    between ``now_ms`` and ``deadline_ms``: None if it fails at ``now_ms``, +inf if it holds even an hour past the
    deadline (a policy that admits at any time). ``admits`` must be monotone and free of side effects: it is
    called about a dozen times (see :meth:`AnalyticsScheduler.cloud_admit`). The dispatcher in
    ``aerodaas.schedulers.dispatch.dispatcher`` sends the result with the task; the cloud executor compares it
    with its clock."""
    if not admits(now_ms):
        return None
    hi = deadline_ms
    if admits(hi):
        far = deadline_ms + 3_600_000.0
        if admits(far):
            return math.inf
        lo, hi = hi, far
    else:
        lo = now_ms
    while hi - lo > 1.0:
        mid = (lo + hi) / 2.0
        if admits(mid):
            lo = mid
        else:
            hi = mid
    return lo


def register_analytics_scheduler(cls: type[AnalyticsScheduler]) -> type[AnalyticsScheduler]:
    """Class decorator: make ``cls`` available by ``cls.name`` in the plug-in registry
    (:mod:`aerodaas.plugins.registry`, kind ``analytics_scheduler``, origin ``decorator in FILE``; the built-in schedulers are
    entry points of this package, see pyproject.toml). Raises ValueError on a duplicate or empty name."""
    if not cls.name:
        raise ValueError(f"{cls.__name__}: an analytics scheduler needs a non-empty 'name'")
    return registry.register(cls, "analytics_scheduler", cls.name)


def analytics_scheduler_names() -> list[str]:
    """Registered names (built-ins, decorators, installed entry points), in registration order."""
    return registry.names("analytics_scheduler")


def analytics_scheduler_class(name: str) -> type[AnalyticsScheduler]:
    """The class registered as ``name`` (built-ins, whatever the application registered with
    :func:`register_analytics_scheduler`, an installed entry point of group ``aerodaas.analytics_schedulers``, or
    ``"module.path:ClassName"``). The runtime carries this class, not its name, to the dispatcher actors: an
    application's class exists only where the application ran (Ray pickles a class defined in the application by
    value). Raises ValueError (:class:`aerodaas.plugins.registry.UnknownPlugin`) naming the known schedulers and
    where each came from."""
    return registry.get("analytics_scheduler", name)


def make_analytics_scheduler(name: str, workload: Workload, **kwargs: Any) -> AnalyticsScheduler:
    """Instantiate the scheduler registered as ``name``. Raises ValueError naming the known schedulers."""
    return analytics_scheduler_class(name)(workload, **kwargs)


def filter_options(name: str, options: Mapping[str, Any]) -> dict[str, Any]:
    """The entries of ``options`` that the scheduler registered as ``name`` accepts (its ``options``), None values
    left out: how a benchmark applies one setting (e.g. ``estimator="max:5"``) to every policy that has it."""
    try:
        accepted = analytics_scheduler_class(name).options
    except ValueError:
        accepted = ()
    return {k: v for k, v in options.items() if k in accepted and v is not None}


def iter_schedulers(names: Iterable[str] | None = None) -> list[type[AnalyticsScheduler]]:
    """The scheduler classes for ``names`` (all registered ones when None)."""
    return [analytics_scheduler_class(n) for n in (names or analytics_scheduler_names())]
