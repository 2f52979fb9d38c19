"""The edge/cloud dispatcher (aerodaas.schedulers.dispatch) with emulated executors: accounting, utility, the baselines'
behaviour, the cloud re-check, timers, thread-safe submission, the ONNX executors, and the Ray actor wrappers on
the session's single-node Ray. A cloud executor lost or out of reach: ``test_cloud_pool_losses.py``."""
from __future__ import annotations

import asyncio
import json
import threading
import time

import pytest

from aerodaas.actors.cloud.executor import CloudExecutor
from aerodaas.schedulers.dispatch.clock import Clock
from aerodaas.schedulers.dispatch.cloud_pool import CloudPool
from aerodaas.schedulers.dispatch.dispatcher import AnalyticsDispatcher
from aerodaas.schedulers.dispatch.edge_executors import EmulatedEdgeExecutor, OnnxEdgeExecutor
from aerodaas.schedulers.dispatch.emulation import Jitter, NetworkModel
from aerodaas.schedulers.analytics_base import (
    TERMINAL_STATES, AnalyticsScheduler, Decision, TaskState, Workload, make_analytics_scheduler, task_utility,
)
from tests.conftest import DATA_DIR, MODEL_DIR, needs_data, needs_workload

WORKLOAD = DATA_DIR / "workloads" / "ocularone_lambda.json"
pytestmark = needs_workload


def workload(load: str = "MEDIUM", deadline_ms: float | None = None) -> Workload:
    """The workload file's ``load``, every model's deadline set to ``deadline_ms`` when given (a test about
    something other than meeting deadlines, which the cloud's wall-clock re-check would refuse on a loaded
    machine)."""
    if deadline_ms is None:
        return Workload.from_file(WORKLOAD, load)
    data = json.loads(WORKLOAD.read_text())
    data["loads"][load] = {m: float(deadline_ms) for m in data["loads"][load]}
    return Workload.from_dict(data, load)


def frames(drones: int, per_s: float, seconds: float, models, offset_ms: float = 0.0) -> list[tuple]:
    """(t_ms, drone, model) rows: each drone sends ``per_s`` frames a second, one task per model per frame."""
    rows, period = [], 1000.0 / per_s
    for d in range(drones):
        t = offset_ms + d * period / drones
        while t < seconds * 1000.0:
            rows += [(t, f"d{d}", m) for m in models]
            t += period
    return sorted(rows, key=lambda r: r[0])


async def drive(policy: AnalyticsScheduler, trace, *, cloud: bool = True, network=None,
                edge_jitter: str = "none", cloud_jitter: str = "none", drain_s: float = 5.0,
                executor: CloudExecutor | None = None):
    """Run ``policy`` on one emulated edge (+ an in-process cloud executor: ``executor``, or a new one) over
    ``trace``; returns (dispatcher, report, pool report)."""
    pool = CloudPool([executor or CloudExecutor("c0")], network=NetworkModel.parse(network),
                     jitter=Jitter.parse(cloud_jitter), seed=1) if cloud else None
    d = AnalyticsDispatcher(policy, EmulatedEdgeExecutor(Jitter.parse(edge_jitter), seed=1), pool)
    await d.start()
    loop = asyncio.get_running_loop()
    base = d.clock.now_ms()  # the trace starts now
    for t_ms, drone, model in trace:
        delay = d.clock.loop_time(loop, base + t_ms) - loop.time()
        if delay > 0:
            await asyncio.sleep(delay)
        d.submit(drone, model, None, base + t_ms)
    report = await d.finish(drain_s)
    pool_report = None
    if pool is not None:
        pool_report = pool.report()
        await pool.close()
    return d, report, pool_report


def check_accounting(d: AnalyticsDispatcher, report: dict) -> None:
    """Every submitted task ended in exactly one terminal state and utility is the sum of task_utility."""
    tasks = d.tasks()
    assert len(tasks) == report["submitted"] == report["terminal"] > 0
    assert report["pending"] == 0 and report["accounting"]["policy_errors"] == 0, report["accounting"]
    assert all(t.state in TERMINAL_STATES for t in tasks)
    assert sum(report["states"].values()) == len(tasks)
    assert report["utility"] == pytest.approx(sum(task_utility(t, d.workload[t.model]) for t in tasks))
    # each task carries its utility and the cost charged for it (what its task record holds)
    assert report["utility"] == pytest.approx(sum(t.utility for t in tasks))
    assert report["cloud_cost"] == pytest.approx(sum(t.cost for t in tasks if t.tier == "cloud"))
    assert report["edge_cost"] == pytest.approx(sum(t.cost for t in tasks if t.tier == "edge"))
    for t in tasks:
        assert t.end_ms is not None and t.reason
        if t.state in (TaskState.DONE_ON_TIME, TaskState.DONE_LATE):
            assert t.tier in ("edge", "cloud") and t.start_ms is not None
            assert (t.end_ms <= t.deadline_ms) == (t.state is TaskState.DONE_ON_TIME)


# ------------------------------------------------------------------------------------------------ baselines
def test_edge_fifo_overloaded_expires_tasks_and_accounts_for_all():
    w = workload("MEDIUM")  # 732 ms of edge work per frame: 4 frames/s overload one edge about 3x
    trace = frames(drones=2, per_s=2, seconds=1.5, models=w.models)
    d, r, _ = asyncio.run(drive(make_analytics_scheduler("EDGE_FIFO", w), trace))
    check_accounting(d, r)
    assert r["states"]["expired_edge"] > 0
    assert r["states"]["done_on_time"] > 0
    assert r["tiers"].get("cloud", 0) == 0 and r["cloud_cost"] == 0
    expired = [t for t in d.tasks() if t.state is TaskState.EXPIRED_EDGE]
    assert all("left when it reached the head of the edge queue" in t.reason and t.tier is None for t in expired)
    assert r["edge_utilisation"] > 0.5
    # the edge executor emulates the profile: jitter none, so no hold is shorter than the profile's edge_ms (how
    # much longer depends on the machine's load: `aerodaas bench schedulers` reports edge_hold_error)
    assert r["timing_ms"]["edge_hold_error"]["n"] > 0
    assert min(d.edge_hold_error.values) >= -1.0, r["timing_ms"]


def test_cloud_only_sends_positive_utility_tasks_and_drops_the_rest_for_cost():
    w = workload("MEDIUM")  # BP: benefit 40 < cloud cost 43
    trace = frames(drones=2, per_s=2, seconds=1.0, models=w.models)
    d, r, pool = asyncio.run(drive(make_analytics_scheduler("CLOUD", w), trace))
    check_accounting(d, r)
    for t in d.tasks():
        if w[t.model].cloud_utility > 0:
            # sent to the cloud and completed there; on time or not is the machine's load (a wall-clock emulation:
            # beside two CPU burners one task of 4 came back late), which the benchmarks measure, not this test
            assert t.tier == "cloud" and t.state in (TaskState.DONE_ON_TIME, TaskState.DONE_LATE), t
        else:
            assert t.state is TaskState.DROPPED_COST and "cloud utility" in t.reason, t
    assert r["cloud_cost"] == pytest.approx(sum(w[t.model].cloud_cost for t in d.tasks() if t.tier == "cloud"))
    assert r["edge_busy_ms"] == 0
    assert pool["sent"] == sum(1 for t in d.tasks() if t.tier == "cloud")


class SendAllToCloud(AnalyticsScheduler):
    """Test policy: every task to the cloud; the default cloud_admit (profile cloud time within the deadline)."""

    name = "TEST_SEND_ALL"

    def submit(self, task, now_ms):
        return [Decision.cloud(task, "test: to the cloud")]

    def _pop_edge(self, now_ms):
        return None, []

    def held_tasks(self):
        return []


def test_cloud_recheck_refuses_a_request_that_arrives_past_its_admit_by_time():
    """The re-check is made when the request reaches the executor (the reference checks right before its Lambda
    call): a request delayed past its admit-by time (a slow Ray hop) is refused and never runs."""
    async def run():
        ex = CloudExecutor("c0")
        now = time.time()
        base = {"model": "HV", "sent": now, "up_ms": 50.0, "down_ms": 50.0, "exec_ms": 30.0, "lead_ms": 0.0,
                "jpeg": None, "meta": None}
        await ex.submit("cl", [dict(base, k=1, admit_by=now - 0.020),   # 20 ms past: refused on arrival
                               dict(base, k=2, admit_by=now + 0.010)])  # admitted; uplink comes after the check
        replies = []
        while len(replies) < 2:
            replies += await ex.collect("cl", 2.0)
        return ex, {r["k"]: r for r in replies}, now

    ex, r, sent = asyncio.run(run())
    assert not r[1]["ok"] and r[1]["error"].startswith("cloud re-check: start") and r[1]["start"] is None
    assert r[2]["ok"] and r[2]["start"] >= sent + 0.050 - 1e-3           # ran after the emulated uplink
    assert r[2]["due"] == pytest.approx(sent + 0.130, abs=0.005)         # 50 up + 30 run + 50 down
    assert (ex.executed, ex.refused) == (1, 1)


class JustInTimeCloud(AnalyticsScheduler):
    """Test policy: hold each task and send it to the cloud at deadline - cloud time - 20 ms (a poll timer). Its
    cloud re-check admits at any time (no admit-by limit): what is under test is when the timer fires, and a poll
    that fires more than 20 ms late on a loaded machine must not turn into a refusal."""

    name = "TEST_JIT"

    def __init__(self, w):
        super().__init__(w)
        self.held: list = []
        self.polls: list[float] = []

    def _due(self, t):
        return t.deadline_ms - self.cloud_estimate_ms(t.model) - 20.0

    def submit(self, task, now_ms):
        self.held.append(task)
        return []

    def next_poll_ms(self):
        return min((self._due(t) for t in self.held), default=None)

    def cloud_admit(self, task, now_ms):
        return True

    def poll(self, now_ms):
        self.polls.append(now_ms)
        due = [t for t in self.held if self._due(t) <= now_ms]
        self.held = [t for t in self.held if t not in due]
        return [Decision.cloud(t, "test: just in time") for t in due]

    def _pop_edge(self, now_ms):
        return None, []

    def held_tasks(self):
        return list(self.held)


class SteppedClock(Clock):
    """A clock the test sets; every read is 1 µs after the one before it (time passes between two reads)."""

    def __init__(self) -> None:
        super().__init__()
        self.t_ms = 0.0

    def now_ms(self) -> float:
        self.t_ms += 0.001
        return self.t_ms


class EndsAtTheDeadline(EmulatedEdgeExecutor):
    """An edge whose every run ends exactly at its task's deadline on ``clock``."""

    def __init__(self, clock: SteppedClock) -> None:
        super().__init__()
        self.clock = clock

    async def run(self, task, workload, edge_id):
        self.clock.t_ms = task.deadline_ms - 0.001  # the dispatcher's next read is the deadline itself
        return None, None


def test_a_task_is_on_time_exactly_when_its_recorded_end_is_not_after_its_deadline():
    """The state and ``end_ms`` come from one clock reading: a task judged on time at its deadline records that
    reading as its end, not a later one (the CI failure of c603586: end 1400.2038 ms, deadline 1400.2004 ms,
    DONE_ON_TIME)."""
    clock = SteppedClock()

    async def run():
        d = AnalyticsDispatcher(make_analytics_scheduler("EDGE_FIFO", workload("LIGHT")), EndsAtTheDeadline(clock),
                                None, clock=clock)
        await d.start()
        for i in range(3):  # arrivals 1 s apart: each can still make its deadline when it reaches the edge
            d.submit("d0", "HV", None, 1000.0 * i)
        return d, await d.finish(1.0)

    d, r = asyncio.run(run())
    check_accounting(d, r)
    assert r["states"]["done_on_time"] == 3
    assert all(t.end_ms == t.deadline_ms for t in d.tasks())


def test_poll_timer_fires_at_next_poll_ms():
    w = workload("LIGHT")
    policy = JustInTimeCloud(w)
    trace = [(0.0, "d0", "HV"), (0.0, "d0", "MD"), (100.0, "d1", "HV")]
    d, r, _ = asyncio.run(drive(policy, trace))
    check_accounting(d, r)
    # all executed; on time or late is the machine's load (1 of 3 on time at load 20-30), for the benchmarks
    assert r["states"]["done_on_time"] + r["states"]["done_late"] == 3, r["states"]
    for t in d.tasks():  # sent at its due time, not at arrival
        assert t.start_ms >= t.deadline_ms - w[t.model].cloud_ms - 20.0 - 1.0 > t.arrival_ms, (t, w[t.model])
    assert len(policy.polls) >= 2
    # no poll fires before its time (how late it fires depends on the machine's load: `aerodaas bench schedulers`)
    assert r["timing_ms"]["poll_lateness"]["n"] >= 2 and min(d.poll_lateness.values) >= -1.0, r["timing_ms"]


def test_held_tasks_are_dropped_when_the_run_ends():
    w = workload("LIGHT")
    policy = JustInTimeCloud(w)

    async def run():
        d = AnalyticsDispatcher(policy, EmulatedEdgeExecutor(), None)
        await d.start()
        d.submit("d0", "HV")
        d.submit("d0", "MD")
        return d, await d.finish(0.05)

    d, r = asyncio.run(run())
    check_accounting(d, r)
    assert r["states"]["dropped_time"] == 2
    assert all(t.reason == "run ended while held by the scheduler" for t in d.tasks())


def test_submit_from_many_threads_loses_nothing():
    w = workload("MEDIUM")
    d = AnalyticsDispatcher(make_analytics_scheduler("EDGE_FIFO", w), EmulatedEdgeExecutor(Jitter("none")),
                            None).start_background()
    n_threads, per_thread = 4, 50

    def worker(k):
        for i in range(per_thread):
            d.submit(f"d{k}", list(w.models)[i % len(w.models)])

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(n_threads)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    ids = [t.task_id for t in d.tasks()]
    assert len(ids) == len(set(ids)) == n_threads * per_thread
    r = d.finish_background(drain_timeout_s=0.5)
    check_accounting(d, r)
    assert r["submitted"] == n_threads * per_thread
    assert r["states"]["expired_edge"] + r["states"]["dropped_time"] > 0  # 200 tasks cannot all run in 0.5 s


# ------------------------------------------------------------------------------------------------ inputs
def test_bad_inputs_raise_clear_errors():
    w = workload("LIGHT")
    d = AnalyticsDispatcher(make_analytics_scheduler("EDGE_FIFO", w), EmulatedEdgeExecutor(), None)
    with pytest.raises(KeyError, match="BP"):
        d.submit("d0", "BP")  # not in the LIGHT workload
    with pytest.raises(RuntimeError, match="not running"):
        d.submit("d0", "HV")  # before start
    with pytest.raises(ValueError, match="network-variability 'bogus:1'"):
        NetworkModel.parse(["bogus:1"])
    with pytest.raises(ValueError, match="must end after"):
        NetworkModel.parse("+100@30-20")
    with pytest.raises(ValueError, match="jitter 'lognormal:x'"):
        Jitter.parse("lognormal:x")
    with pytest.raises(ValueError, match="mode"):
        CloudPool([CloudExecutor()], mode="fast")
    with pytest.raises(TypeError, match="AnalyticsScheduler"):
        AnalyticsDispatcher(object(), EmulatedEdgeExecutor())


def test_network_model_is_seeded_and_has_episodes_and_a_walk():
    from aerodaas.schedulers.dispatch.emulation import seeded_rng

    m = NetworkModel.parse(["normal:50,10", "+300@2-4", "walk:20,100,0.5"], seed=3)
    a = [m.sample(t, seeded_rng(3, i)) for i, t in enumerate(range(0, 6000, 100))]
    b = [NetworkModel.parse(["normal:50,10", "+300@2-4", "walk:20,100,0.5"], seed=3).sample(t, seeded_rng(3, i))
         for i, t in enumerate(range(0, 6000, 100))]
    assert a == b
    inside = [m.offset_ms(t) for t in range(2000, 4000, 100)]
    outside = [m.offset_ms(t) for t in range(4000, 6000, 100)]
    assert min(inside) >= 300 and max(outside) <= 100
    assert all(0 <= m.offset_ms(t) - (300 if 2000 <= t < 4000 else 0) <= 100 for t in range(0, 6000, 50))


# ------------------------------------------------------------------------------------------------ real executors
@needs_data
def test_onnx_executors_run_the_detector_on_the_edge_and_on_a_jpeg_in_the_cloud(data_env):
    import cv2

    photo = cv2.imread(str(DATA_DIR / "imagery" / "brighton_beach" / "DJI_0031.JPG"))
    frame = cv2.resize(photo[720 - 112:720 + 112, 2540 - 150:2540 + 150], (640, 480))  # zoomed on a silver car
    w = workload("LIGHT")

    class EdgeHVCloudMD(SendAllToCloud):
        name = "TEST_SPLIT"

        def __init__(self, w):
            super().__init__(w)
            self.q = []

        def submit(self, task, now_ms):
            if task.model == "HV":
                self.q.append(task)
                return []
            return [Decision.cloud(task, "test: MD to the cloud")]

        def _pop_edge(self, now_ms):
            return (self.q.pop(0) if self.q else None), []

        def cloud_admit(self, task, now_ms):
            return True

    async def run():
        kw = {"model_path": str(MODEL_DIR / "yolox_nano.onnx"), "score_threshold": 0.2}
        pool = CloudPool([CloudExecutor("c0", mode="real", threads=1, detector_for="yolox_nano",
                                        detector_kwargs=kw)], mode="real", jitter=Jitter("none"))
        d = AnalyticsDispatcher(EdgeHVCloudMD(w), OnnxEdgeExecutor("yolox_nano", kw), pool)
        await d.start()
        d.submit("d0", "HV", frame)
        d.submit("d0", "MD", frame)
        r = await d.finish(20.0)
        await pool.close()
        return d, r

    d, r = asyncio.run(run())
    assert r["terminal"] == 2 and r["accounting"]["policy_errors"] == 0
    edge, cloud = d.tasks()
    assert edge.tier == "edge" and cloud.tier == "cloud"
    for t in (edge, cloud):
        assert t.state in (TaskState.DONE_ON_TIME, TaskState.DONE_LATE), t.reason
        assert any(det.class_name == "car" for det in t.result), t.result
    # same model, same image (cloud via JPEG): the same cars within JPEG noise
    assert abs(len([x for x in edge.result if x.class_name == "car"]) - len([x for x in cloud.result if x.class_name == "car"])) <= 2


# ------------------------------------------------------------------------------------------------ Ray actors
def test_edge_host_and_cloud_executor_actors_on_the_session_ray(ray_session):
    import ray

    from aerodaas.actors.cloud.executor import start_cloud_executors
    from aerodaas.bench.edge_host import EdgeHostActor

    w = workload("LIGHT", deadline_ms=60_000.0)  # the round trip under test, not meeting deadlines (see workload)
    cloud = start_cloud_executors(1)  # single node: tier in(edge,cloud)
    host = EdgeHostActor.options(label_selector={"tier": "edge"}).remote("host-test")
    try:
        info = ray.get(host.info.remote())
        assert info["labels"].get("tier") == "edge"
        start = time.time() + 1.0
        ray.get(host.configure.remote(scheduler="CLOUD", workload=w, edge_ids=["e0", "e1"], cloud_executors=cloud,
                                      start_epoch=start, cloud_jitter="none"))
        trace = [(float(t), f"e{i % 2}", f"d{i}", m) for i, t in enumerate(range(0, 1000, 100)) for m in ("HV", "MD")]
        out = ray.get(host.run_trace.remote(trace, 5.0))
        reps = out["edges"]
        assert sum(r["submitted"] for r in reps) == len(trace)
        assert all(r["pending"] == 0 and r["terminal"] == r["submitted"] for r in reps)
        # every task executed in the cloud and answered (on time or late: how many meet their wall-clock deadline on
        # a loaded 2-core machine is a benchmark's question, `aerodaas bench schedulers --runtime`)
        assert sum(r["states"].get("done_on_time", 0) + r["states"].get("done_late", 0) for r in reps) == len(trace), \
            [r["states"] for r in reps]
        assert out["cloud"]["sent"] == len(trace) and out["cloud"]["losses"] == [], out["cloud"]
        assert len(out["cloud_reply_margin_ms"]) == len(trace)  # each reply's margin to its due time measured
    finally:
        ray.kill(host)
        for c in cloud:
            ray.kill(c)


# ------------------------------------------------------------------------------------------------ benchmark trace
def test_benchmark_trace_is_seeded_and_follows_the_arrival_process():
    from aerodaas.bench.workload import edge_layout, make_trace

    w = workload("HEAVY")
    a = make_trace(w, drones=10, duration_s=3.0, seed=4, drones_per_edge=3, fps=1.0)
    assert a == make_trace(w, drones=10, duration_s=3.0, seed=4, drones_per_edge=3, fps=1.0)
    assert a != make_trace(w, drones=10, duration_s=3.0, seed=5, drones_per_edge=3, fps=1.0)
    assert [len(g) for g in edge_layout(10, 3)] == [3, 3, 3, 1]
    assert len(a) == 10 * 3 * len(w.models)  # 3 frames per drone, one task per model per frame
    assert [r[0] for r in a] == sorted(r[0] for r in a) and all(0 <= r[0] < 3000 for r in a)
    frames_of = {}
    for t, edge, drone, model in a:
        frames_of.setdefault((drone, t), []).append(model)
        assert edge == f"edge{int(drone[1:]) // 3:02d}"
    assert all(sorted(ms) == sorted(w.models) for ms in frames_of.values())
    assert len({tuple(ms) for ms in frames_of.values()}) > 1  # the model order is shuffled per frame
    per_drone = {}
    for drone, t in frames_of:
        per_drone.setdefault(drone, []).append(t)
    for ts in per_drone.values():
        ts.sort()
        assert [round(b - a_, 3) for a_, b in zip(ts, ts[1:])] == [1000.0, 1000.0]
    with pytest.raises(ValueError, match="drones_per_edge"):
        edge_layout(10, 0)
