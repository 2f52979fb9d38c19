"""The edge/cloud dispatcher (aerodaas.schedulers.dispatch) on the cloud re-check, the poll timer's lateness and the
loss of the last cloud executor, with an emulated edge and an in-process cloud executor: judged from the records of
the run (the requests and replies the executor saw, the times the dispatcher stamped on each task and poll, the
calls the policy heard, in their order), not from whether a task came back on time by a loaded event loop's clock,
so they hold on a loaded machine and run in the slow tier's other lane, not the real-time one."""
from __future__ import annotations

import asyncio

import pytest
from aerodaas.actors.cloud.executor import CloudExecutor
from aerodaas.schedulers.analytics_base import TaskState, Workload
from aerodaas.schedulers.analytics_dems import Gems
from aerodaas.schedulers.dispatch.cloud_pool import CloudPool
from aerodaas.schedulers.dispatch.dispatcher import AnalyticsDispatcher
from aerodaas.schedulers.dispatch.edge_executors import EmulatedEdgeExecutor
from aerodaas.schedulers.dispatch.emulation import Jitter

from tests.cluster.test_cloud_pool_losses import DyingExecutor
from tests.cluster.test_edgecloud import JustInTimeCloud, SendAllToCloud, check_accounting, drive, workload
from tests.conftest import needs_workload

pytestmark = needs_workload

_DONE = (TaskState.DONE_ON_TIME, TaskState.DONE_LATE)


class RecordingExecutor(CloudExecutor):
    """An in-process cloud executor that keeps every request it was sent and every reply it made, by key."""

    def __init__(self, name: str = "c0") -> None:
        super().__init__(name)
        self.requests: dict[int, dict] = {}
        self.replies: dict[int, dict] = {}

    async def submit(self, client, reqs):
        self.requests.update((r["k"], dict(r)) for r in reqs)
        return await super().submit(client, reqs)

    def _reply(self, client, req, ok, start, end, result=None, error=None, due=None):
        self.replies[req["k"]] = {"ok": ok, "start": start, "end": end, "error": error, "due": due}
        super()._reply(client, req, ok, start, end, result, error, due)


@pytest.mark.slow  # 2 x ~1 s of wall-clock emulation, judged from the run's records: the slow tier's other lane
def test_network_latency_after_the_recheck_makes_a_task_late_not_refused():
    """HV (LIGHT: deadline 650 ms, cloud 398 ms, so admitted until 252 ms after arrival) sent to the cloud at once.
    The emulated network's round trip comes after the executor's re-check: 600 ms more (as in the reference, whose
    check precedes its Lambda call) is admitted when the request arrives, runs, and comes back ~998 ms after it was
    sent: late, cost paid, never refused. 100 ms more: admitted, run, and scheduled back 498 ms after sending,
    inside the deadline. Whether it then lands on time by the event loop's clock is the machine's load (the
    benchmarks measure that), so it is judged from the executor's schedule (``due - sent``) and the round trip the
    dispatcher measured (never shorter than that schedule)."""
    w = workload("LIGHT")
    trace = [(0.0, "d0", "HV"), (10.0, "d1", "HV")]
    for extra_ms, intended_ms in ((600, 998), (100, 498)):
        ex = RecordingExecutor()
        d, r, _ = asyncio.run(drive(SendAllToCloud(w), trace, network=f"const:{extra_ms}", executor=ex))
        check_accounting(d, r)
        assert (ex.executed, ex.refused) == (2, 0), (extra_ms, r["states"])  # the re-check admitted both
        assert all(t.tier == "cloud" and t.state in _DONE for t in d.tasks()), r["states"]
        assert r["cloud_cost"] == 2 * w["HV"].cloud_cost  # ran on the cloud: charged
        assert set(ex.requests) == set(ex.replies) and len(ex.requests) == 2
        for k, req in ex.requests.items():
            rep = ex.replies[k]
            # a re-check was made (admit-by time set) and passed; the network's delay was added after it
            assert req["admit_by"] is not None and rep["ok"] and rep["error"] is None, (req, rep)
            assert req["up_ms"] + req["down_ms"] == pytest.approx(extra_ms)
            assert 1000.0 * (rep["due"] - req["sent"]) == pytest.approx(intended_ms, abs=1.0), (req, rep)
        lat = [t.end_ms - t.start_ms for t in d.tasks()]
        assert all(x >= intended_ms - 1.0 for x in lat), lat  # released at its due time, never before
        if extra_ms == 600:  # 998 > 650: late whatever the load (a load only adds to it)
            assert r["states"]["done_late"] == 2 and r["utility"] < 0, r["states"]


class OverdueCloud(JustInTimeCloud):
    """Test policy: each task is due 200 ms before it arrived, as when a policy's latency estimate jumps and its
    triggers move into the past."""

    name = "TEST_OVERDUE"

    def _due(self, t):
        return t.arrival_ms - 200.0


@pytest.mark.slow  # ~1 s, judged from the stamps of the dispatcher's clock: the slow tier's other lane
def test_poll_lateness_times_the_timer_not_a_due_time_already_past_when_armed():
    """A poll armed for a due time already past is due when it is armed: its lateness is measured from then, not
    from the past due time. Each task is submitted once the one before it has left (so each has a poll of its
    own, whatever the load). A poll's recorded lateness is then at most the time from its task's arrival (the
    earliest it could have been armed) to the poll (the clock reading the policy was given); measured from the
    due time it would be 200 ms more. How late the timer fires is the machine's load (`aerodaas bench
    schedulers`), not asserted."""
    policy = OverdueCloud(workload("LIGHT"))

    async def run():
        d = AnalyticsDispatcher(policy, EmulatedEdgeExecutor(), CloudPool([CloudExecutor("c0")],
                                                                          jitter=Jitter("none")))
        await d.start()
        for drone, model in (("d0", "HV"), ("d1", "HV"), ("d2", "MD")):
            d.submit(drone, model)
            while policy.held:  # until the poll has sent it
                await asyncio.sleep(0.005)
        r = await d.finish(5.0)
        await d.cloud.close()
        return d, r

    d, r = asyncio.run(run())
    check_accounting(d, r)
    tasks = d.tasks()
    assert all(t.tier == "cloud" and t.state in _DONE for t in tasks), r["states"]
    lateness = d.poll_lateness.values
    assert len(policy.polls) == len(lateness) == r["timing_ms"]["poll_lateness"]["n"] == 3, (policy.polls, lateness)
    for poll_ms, late_ms, t in zip(policy.polls, lateness, tasks):
        # sent by this poll: the dispatcher stamped its start right after the policy's poll
        assert poll_ms <= t.start_ms and t.arrival_ms < poll_ms, (poll_ms, t)
        # armed no earlier than its task's arrival (measured from the due time: 200 ms more than this bound)
        assert 0.0 <= late_ms <= poll_ms - t.arrival_ms + 1.0, (late_ms, poll_ms, t.arrival_ms, policy._due(t))


class HearingGems(Gems):
    """GEMS that records, for every cloud task it hears of as FAILED, whether it already knew the cloud was gone."""

    def __init__(self, w, **options):
        super().__init__(w, **options)
        self.failures_heard: list[tuple[int, bool]] = []  # (task id, cloud_available when told)

    def on_cloud_done(self, task, now_ms, latency_ms):
        if task.state is TaskState.FAILED:
            self.failures_heard.append((task.task_id, self.cloud_available))
        return super().on_cloud_done(task, now_ms, latency_ms)


@pytest.mark.slow  # ~6 s of wall-clock emulation, judged from the order of the policy's calls: the other lane
def test_losing_the_last_executor_tells_the_policy_before_failing_its_tasks():
    """When the last cloud executor dies, the policy must already know the cloud is gone when it hears that the
    tasks in flight there failed: otherwise GEMS's gatekeeper counts the failures as misses and sends its queued
    edge tasks to a cloud that no longer exists (each then dropped as "cloud unavailable"). Judged from what the
    policy was told and in which order (every failure heard with the cloud already unavailable), not from its
    on-time fraction before the loss, which is the event loop's clock."""
    # one model, 100 ms on the edge, 1500 ms on the cloud, 2500 ms deadline: one task every 25 ms overloads the
    # edge 4x, so its queue is full of tasks the cloud could still finish, and rejected tasks are released to the
    # cloud just in time (990 ms after arrival) and in flight for 1.5 s
    w = Workload.from_dict({"models": {"A": {"edge_ms": 100, "cloud_ms": 1500, "benefit": 100, "edge_cost": 1,
                                             "cloud_cost": 10}},
                            "loads": {"T": {"A": 2500}}}, "T")

    async def run():
        ex = DyingExecutor("c0")
        pool = CloudPool([ex], jitter=Jitter("none"))
        policy = HearingGems(w)
        d = AnalyticsDispatcher(policy, EmulatedEdgeExecutor(), pool)
        await d.start()
        for _ in range(100):  # 2.5 s
            d.submit("d0", "A")
            await asyncio.sleep(0.025)
        state = len(pool._inflight), list(policy.failures_heard)
        ex.dead = True
        await asyncio.sleep(0.2)
        r = await d.finish(3.0)
        await pool.close()
        return d, r, policy, state

    d, r, policy, (in_flight, failures_before) = asyncio.run(run())
    check_accounting(d, r)
    assert failures_before == [] and in_flight > 5 and r["states"]["failed"] >= in_flight  # the loss hit hard
    heard = policy.failures_heard
    assert len(heard) >= in_flight and not [h for h in heard if h[1]], heard  # each failure: cloud already gone
    moved_to_nowhere = [t for t in d.tasks() if "gatekeeper" in (t.reason or "") and "cloud unavailable" in t.reason]
    assert moved_to_nowhere == []
    assert r["cloud_availability_changes"][0]["available"] is False
