"""The cloud pool (aerodaas.schedulers.dispatch.cloud_pool) when a cloud executor is lost or out of reach, with
in-process executors that fail as Ray calls do: a death fails or retries the tasks in flight and tells the policy;
an answer or a submit call lost on the way (Ray's ``ActorUnavailableError``) loses no reply and runs no task twice;
an executor unreachable for ``unavailable_after_ms`` counts as dead and gets no new task meanwhile."""
from __future__ import annotations

import asyncio
import time

import pytest
from ray.exceptions import ActorUnavailableError  # imported here: the first import takes ~0.5 s, not on a test's loop

from aerodaas.actors.cloud.executor import CloudExecutor
from aerodaas.schedulers.dispatch.cloud_pool import CloudPool
from aerodaas.schedulers.dispatch.dispatcher import AnalyticsDispatcher
from aerodaas.schedulers.dispatch.edge_executors import EmulatedEdgeExecutor
from aerodaas.schedulers.dispatch.emulation import Jitter
from aerodaas.schedulers.analytics_base import TaskState, make_analytics_scheduler
from tests.cluster.test_edgecloud import check_accounting, workload
from tests.conftest import needs_workload

pytestmark = needs_workload


class DyingExecutor(CloudExecutor):
    """An in-process cloud executor whose node is lost when ``dead`` is set: its outstanding ``collect`` raises,
    as a Ray call to an actor on a removed node does."""

    dead = False

    async def collect(self, client, max_wait_s=5.0, ack=None):
        while not self.dead:
            await asyncio.sleep(0.01)
        raise RuntimeError("node lost")


def test_cloud_loss_in_process_fails_in_flight_tasks_and_tells_the_policy():
    """An executor that dies (its calls raise) takes its in-flight tasks with it (no second executor: FAILED), and
    the policy hears that the cloud is gone: CLOUD then runs new tasks on the edge (its fallback), until a
    replacement executor is added and they go to the cloud again."""
    w = workload("LIGHT")

    async def run():
        ex = DyingExecutor("c0")
        pool = CloudPool([ex], jitter=Jitter("none"))
        d = AnalyticsDispatcher(make_analytics_scheduler("CLOUD", w), EmulatedEdgeExecutor(), pool)
        await d.start()
        d.submit("d0", "HV")
        d.submit("d0", "MD")
        await asyncio.sleep(0.1)
        ex.dead = True
        await asyncio.sleep(0.1)
        d.submit("d1", "HV")
        await asyncio.sleep(0.05)
        await pool.add_executor(CloudExecutor("c1"))  # a replacement: the cloud is back
        d.submit("d2", "HV")
        r = await d.finish(2.0)
        rep = pool.report()
        await pool.close()
        return d, r, rep

    d, r, rep = asyncio.run(run())
    check_accounting(d, r)
    first, late, back = d.tasks()[:2], d.tasks()[2], d.tasks()[3]
    assert all(t.state is TaskState.FAILED and t.tier == "cloud" and "died" in t.reason for t in first)
    assert late.state is TaskState.DONE_ON_TIME and late.tier == "edge"
    assert back.state is TaskState.DONE_ON_TIME and back.tier == "cloud"
    assert r["cloud_cost"] == sum(w[t.model].cloud_cost for t in (*first, back))  # charged: they ran there
    assert r["edge_cost"] == w[late.model].edge_cost
    lost, regained = r["cloud_availability_changes"]
    assert lost["available"] is False and ev_time(rep) == pytest.approx(lost["at_s"], abs=0.05)
    assert regained["available"] is True and regained["at_s"] > lost["at_s"]
    (ev,) = rep["losses"]
    assert late.arrival_ms / 1000.0 > ev["at_s"]
    assert ev["in_flight"] == 2 and ev["failed"] == 2 and ev["retried"] == 0 and "node lost" in ev["error"]


def _two_tasks_through(ex: CloudExecutor, w) -> tuple:
    """An HV and an MD task of one drone through a CLOUD dispatcher whose pool has the one executor ``ex``, run to
    the end (5 s at most): ``(dispatcher, its finish() report, the pool's report)``."""
    async def run():
        pool = CloudPool([ex], jitter=Jitter("none"))
        d = AnalyticsDispatcher(make_analytics_scheduler("CLOUD", w), EmulatedEdgeExecutor(), pool)
        await d.start()
        d.submit("d0", "HV")
        d.submit("d0", "MD")
        r = await d.finish(5.0)
        rep = pool.report()
        await pool.close()
        return d, r, rep

    return asyncio.run(run())


class FlakyExecutor(CloudExecutor):
    """An in-process cloud executor whose first ``unavailable`` answers carrying replies are lost on the way back:
    the call raises Ray's ``ActorUnavailableError`` after the executor handed the replies out, as a call to a live
    actor over a broken connection does ("the task may or may not have been executed")."""

    unavailable = 1

    async def collect(self, client, max_wait_s=5.0, ack=None):
        out = await super().collect(client, max_wait_s, ack)
        if out and self.unavailable > 0:
            self.unavailable -= 1
            raise ActorUnavailableError("connection reset", None)
        return out


@pytest.mark.parametrize("lost_answers", [1, 3])
def test_an_executor_briefly_unavailable_loses_no_reply_and_stays(lost_answers):
    """The answers of ``collect`` calls lost on the way back: the executor keeps its replies until the pool
    acknowledges them, so both tasks come back DONE from the cloud, nothing counts as lost and the executor stays
    in the pool."""
    ex = FlakyExecutor("c0")
    ex.unavailable = lost_answers
    d, r, rep = _two_tasks_through(ex, workload("LIGHT"))
    check_accounting(d, r)
    assert ex.unavailable == 0  # the answers were lost
    # done (on time or late: each lost answer costs a 0.2 s pause), in the cloud
    assert [(t.state in (TaskState.DONE_ON_TIME, TaskState.DONE_LATE), t.tier) for t in d.tasks()] == [(True, "cloud")] * 2
    assert rep["losses"] == [] and [e["alive"] for e in rep["executors"]] == [True] and rep["in_flight"] == 0


class UnreachableExecutor(CloudExecutor):
    """An in-process cloud executor on a node that died: requests vanish, and every ``collect`` raises Ray's
    ``ActorUnavailableError``, as calls to an actor on a lost node do until Ray learns of the death."""

    async def submit(self, client, reqs):
        return len(reqs)

    async def collect(self, client, max_wait_s=5.0, ack=None):
        await asyncio.sleep(0.02)
        raise ActorUnavailableError("failed to connect: connection refused", None)


def test_an_executor_unreachable_for_unavailable_after_ms_counts_as_dead_and_gets_no_new_task_meanwhile():
    """c0 is unreachable from the start: the task it got is retried on c1 once c0 counts as dead (after
    ``unavailable_after_ms``), and the tasks submitted while it was only unreachable went to c1 straight away."""
    w = workload("LIGHT")

    async def run():
        c0, c1 = UnreachableExecutor("c0"), CloudExecutor("c1")
        pool = CloudPool([c0, c1], jitter=Jitter("none"), unavailable_after_ms=2000.0)
        d = AnalyticsDispatcher(make_analytics_scheduler("CLOUD", w), EmulatedEdgeExecutor(), pool)
        await d.start()
        d.submit("d0", "HV")
        d.submit("d0", "HV")  # round robin: one each
        while pool.report()["executors"][0]["reachable"]:  # until c0's first poll has failed
            await asyncio.sleep(0.01)
        assert pool.report()["executors"][0]["alive"]
        for _ in range(4):
            d.submit("d1", "HV")
        r = await d.finish(8.0)
        rep = pool.report()
        await pool.close()
        st = await c1.stats()
        return d, r, rep, st["executed"] + st["refused"]  # refused: its wall-clock re-check, on a loaded machine

    d, r, rep, reached_c1 = asyncio.run(run())
    check_accounting(d, r)
    (ev,) = rep["losses"]
    assert ev["name"] == "c0" and "ActorUnavailableError" in ev["error"] and ev["at_s"] >= 2.0, ev
    assert ev["in_flight"] == 1 and ev["retried"] + ev["failed"] == 1, ev  # only the task sent before it was seen
    assert reached_c1 == 5 + ev["retried"], [(t.state.value, t.tier, t.reason) for t in d.tasks()]
    assert all(t.tier == "cloud" for t in d.tasks())


class LostSubmitExecutor(CloudExecutor):
    """An in-process cloud executor whose first ``lost`` submit calls raise Ray's ``ActorUnavailableError``, the
    batch accepted first (``arrived``: the answer was lost on the way back) or not (the call never arrived)."""

    lost = 1
    arrived = True

    async def submit(self, client, reqs):
        n = await super().submit(client, reqs) if self.arrived or self.lost == 0 else 0
        if self.lost > 0:
            self.lost -= 1
            raise ActorUnavailableError("connection reset", None)
        return n


@pytest.mark.parametrize("arrived", [True, False], ids=["answer-lost", "call-lost"])
def test_a_submit_call_lost_on_the_way_is_sent_again_and_each_task_runs_once(arrived):
    """Two submit calls fail as Ray calls to a live actor can ("may or may not have been executed"): the pool
    sends the batch again, the executor runs each task once (a request it already has is ignored), and both
    tasks come back DONE from the cloud, not failed by the watchdog as having no reply (minute-long deadlines: the
    resent batch arrives 0.4 s late, past a LIGHT task's admit-by time)."""
    ex = LostSubmitExecutor("c0")
    ex.lost, ex.arrived = 2, arrived
    d, r, rep = _two_tasks_through(ex, workload("LIGHT", deadline_ms=60_000.0))
    check_accounting(d, r)
    assert ex.lost == 0  # both calls failed
    assert ex.executed + ex.refused == 2, (ex.executed, ex.refused)  # each task reached the executor once
    assert [(t.state in (TaskState.DONE_ON_TIME, TaskState.DONE_LATE), t.tier) for t in d.tasks()] == \
        [(True, "cloud")] * 2, [(t.state.value, t.tier, t.reason) for t in d.tasks()]
    assert rep["losses"] == [] and rep["in_flight"] == 0 and rep["retried"] == 0


class RaisingSubmitExecutor(CloudExecutor):
    """An in-process cloud executor, alive, whose ``submit`` raises (an error of its own, as a Ray call returns a
    ``RayTaskError`` for an exception in the actor): it takes no task."""

    async def submit(self, client, reqs):
        raise ValueError("cannot take the batch")


def test_a_batch_an_executor_raises_on_is_retried_elsewhere_not_left_to_the_watchdog():
    """A live executor whose submit raises: the pool retries the batch's tasks on the other executor at once (both
    DONE from the cloud) instead of leaving them unanswered until the watchdog fails them 10 s past their
    deadline; the raising executor stays alive."""
    w = workload("LIGHT", deadline_ms=60_000.0)

    async def run():
        bad, good = RaisingSubmitExecutor("c0"), CloudExecutor("c1")
        pool = CloudPool([bad, good], jitter=Jitter("none"))
        d = AnalyticsDispatcher(make_analytics_scheduler("CLOUD", w), EmulatedEdgeExecutor(), pool)
        await d.start()
        d.submit("d0", "HV")
        d.submit("d0", "MD")  # round robin: one to each
        r = await d.finish(5.0)
        rep = pool.report()
        await pool.close()
        return d, r, rep, (await good.stats())["executed"]

    d, r, rep, executed = asyncio.run(run())
    check_accounting(d, r)
    assert [(t.state in (TaskState.DONE_ON_TIME, TaskState.DONE_LATE), t.tier) for t in d.tasks()] == \
        [(True, "cloud")] * 2, [(t.state.value, t.tier, t.reason) for t in d.tasks()]
    assert executed == 2 and rep["retried"] == 1 and rep["losses"] == [], rep
    assert [e["alive"] for e in rep["executors"]] == [True, True], rep["executors"]


def test_a_closed_pool_sends_nothing_again():
    """A submit call lost on the way (the batch never arrived), then the pool closed before its resend: the resend
    is cancelled with it, so the executor, which has forgotten the client, never runs the task."""
    ex = LostSubmitExecutor("c0")
    ex.lost, ex.arrived = 1, False

    async def run():
        pool = CloudPool([ex], jitter=Jitter("none"))
        d = AnalyticsDispatcher(make_analytics_scheduler("CLOUD", workload("LIGHT", deadline_ms=60_000.0)),
                                EmulatedEdgeExecutor(), pool)
        await d.start()
        d.submit("d0", "HV")
        while ex.lost:  # the first submit call has failed: its resend waits 0.2 s
            await asyncio.sleep(0.005)
        await pool.close()
        await asyncio.sleep(0.5)
        return await ex.stats()

    st = asyncio.run(run())
    assert st["executed"] + st["refused"] == 0, st


def test_an_executor_forgets_request_keys_after_its_window(monkeypatch):
    """A request key is remembered for ``_ACCEPTED_FOR_S``: sent again within it, ignored; after it (a client that
    stopped, a key long answered), forgotten, with the client's table."""
    import aerodaas.actors.cloud.executor as executor

    monkeypatch.setattr(executor, "_ACCEPTED_FOR_S", 0.2)

    async def run():
        ex = CloudExecutor("c0")
        req = {"model": "HV", "sent": time.time(), "up_ms": 0.0, "down_ms": 0.0, "exec_ms": 1.0, "admit_by": None,
               "jpeg": None, "meta": None, "lead_ms": 0.0, "k": 1}
        first, again = await ex.submit("a", [req]), await ex.submit("a", [req])
        await asyncio.sleep(0.3)
        other = await ex.submit("b", [req])  # another client's submit forgets what has aged out
        forgotten = "a" not in ex._accepted
        later = await ex.submit("a", [req])
        await ex.reset()
        return first, again, other, forgotten, later

    assert asyncio.run(run()) == (1, 0, 1, True, 1)


def test_the_executor_hands_a_reply_out_again_until_acknowledged():
    """``collect`` with ``ack``: a reply not acknowledged comes again with the next call, an acknowledged one never;
    without ``ack`` each reply is handed out once."""
    async def run():
        ex = CloudExecutor("c0")
        now = time.time()
        req = {"model": "HV", "sent": now, "up_ms": 0.0, "down_ms": 0.0, "exec_ms": 1.0, "admit_by": None,
               "jpeg": None, "meta": None, "lead_ms": 0.0}
        await ex.submit("a", [{**req, "k": 1}, {**req, "k": 2}])
        first = await ex.collect("a", 2.0, [])
        again = await ex.collect("a", 0.05, [])  # the first answer was "lost": nothing acknowledged
        await ex.submit("a", [{**req, "k": 3}])
        await asyncio.sleep(0.05)
        later = await ex.collect("a", 2.0, [r["k"] for r in again])
        done = await ex.collect("a", 0.05, [r["k"] for r in later])
        await ex.submit("b", [{**req, "k": 7}])
        once = await ex.collect("b", 2.0)
        none = await ex.collect("b", 0.05)
        return first, again, later, done, once, none

    first, again, later, done, once, none = asyncio.run(run())
    keys = lambda rs: sorted(r["k"] for r in rs)  # noqa: E731
    assert keys(first) == keys(again) == [1, 2]
    assert keys(later) == [3] and done == []
    assert keys(once) == [7] and none == []


def ev_time(pool_report: dict) -> float:
    return pool_report["losses"][0]["at_s"]
