"""DEMS-A against DEMS on a cloud latency step, on the edge/cloud dispatcher (aerodaas.schedulers.dispatch) with an
emulated edge and an in-process cloud executor: judged from the dispatcher's own records (the round trips it
measured, the estimate and trigger each task was given), not from wall-clock lateness, so it holds on a loaded
machine and runs in the slow tier's other lane, not the real-time one."""
from __future__ import annotations

import asyncio
import re

import pytest
from aerodaas.schedulers.analytics_base import TaskState, make_analytics_scheduler
from aerodaas.schedulers.dispatch.dispatcher import AnalyticsDispatcher

from tests.cluster.test_edgecloud import check_accounting, drive, frames, workload
from tests.conftest import needs_workload

pytestmark = needs_workload

#: HV's cloud round trip once the network step is in force (profile 398 ms + 200 ms) and its deadline (LIGHT)
HV_STEPPED_MS, HV_DEADLINE_MS = 598.0, 650.0


def after_ten_stepped_completions(d: AnalyticsDispatcher) -> list:
    """The tasks of ``d`` the policy placed off the edge (sent to the cloud, or dropped because the cloud time does
    not fit; cool-down probes left out) that arrived after the dispatcher had measured at least 10 cloud round
    trips, the last 10 of them all the stepped one or longer (:data:`HV_STEPPED_MS`): what a window of 10 measured
    completions has seen when the policy decides on the task (a completion's ``end_ms`` is the dispatcher's clock
    reading when it heard of it, so one before a task's arrival was heard of before the task was submitted)."""
    executed = (TaskState.DONE_ON_TIME, TaskState.DONE_LATE)
    done = sorted((t for t in d.tasks() if t.tier == "cloud" and t.state in executed), key=lambda t: t.end_ms)
    out = []
    for t in d.tasks():
        off_edge = t.tier == "cloud" or (t.state is TaskState.DROPPED_TIME and "ms exceeds the" in t.reason)
        seen = [c.end_ms - c.start_ms for c in done if c.end_ms < t.arrival_ms][-10:]
        if off_edge and "probe" not in t.notes and len(seen) == 10 and min(seen) >= HV_STEPPED_MS - 1.0:
            out.append(t)
    return out


@pytest.mark.slow  # 2 x 11 s of wall-clock emulation (mostly sleep), judged from decisions: the slow tier's other lane
def test_dems_a_adapts_to_a_latency_step_on_the_runtime_where_dems_keeps_sending_late():
    """HV (deadline 650, cloud 398) at twice the edge's rate: DEMS holds the overflow and releases it just in time
    (cloud trigger = deadline - estimate - 10 ms). From 1.5 s every cloud call takes 200 ms more. DEMS keeps its
    398 ms estimate, so its triggers leave too little time and its cloud tasks come back late, cost paid. DEMS-A's
    window of the last 10 measured completions moves its estimate to the stepped round trip (~598 ms): from then on
    it sends a task only with room for that round trip before the deadline, or drops it for time.

    Judged from the dispatcher's own records, not from DEMS-A's wall-clock lateness: a loaded machine only adds to
    a measured round trip, so DEMS stays late whatever the load, but whether DEMS-A's tasks land inside a 10 ms
    buffer is the machine's (0.58 late beside CPU burners at load 2-12). What DEMS-A decides is not: the estimate
    each task was held with (``notes["cloud_ms"]``, or named in its drop reason) and the trigger it was given
    (``notes["trigger_ms"]``), after 10 stepped round trips it measured itself."""
    w = workload("LIGHT")
    assert (w["HV"].deadline_ms, w["HV"].cloud_ms) == (HV_DEADLINE_MS, HV_STEPPED_MS - 200.0)
    trace = frames(12, 1.0, 6.0, ["HV"])
    out = {name: asyncio.run(drive(make_analytics_scheduler(name, w), trace, network="+200@1.5-60"))
           for name in ("DEMS", "DEMS-A")}
    after = {}
    for name, (d, r, _) in out.items():
        check_accounting(d, r)
        after[name] = after_ten_stepped_completions(d)
        cloud = sorted((t.arrival_ms, t.state.value, t.end_ms - (t.start_ms or 0), t.notes)
                       for t in d.tasks() if t.tier == "cloud")
        assert len(after[name]) >= 5, (name, r["states"], cloud)
    # DEMS: sent with the profile's 398 ms and released >= 192 ms after arrival, so back >= 140 ms past the
    # deadline, whatever the load (or refused by the executor's re-check when a loaded hop delayed it)
    # (a task DEMS evicted from the edge too late for even 398 ms is dropped for time: not what this is about)
    sent = [t for t in after["DEMS"] if t.tier == "cloud"]
    assert all(t.notes["cloud_ms"] == HV_STEPPED_MS - 200.0 for t in sent), [t.notes for t in sent]
    assert not [t for t in sent if t.state is TaskState.DONE_ON_TIME], [t.state for t in sent]
    assert sum(t.state is TaskState.DONE_LATE for t in sent) >= 5, [t.state for t in sent]
    # DEMS-A: each decided with the mean of its window, the stepped round trip or more (within its 10 ms drift
    # threshold); sent with a trigger that leaves that round trip before the deadline (at ~608 ms the trigger is
    # already inside the 50 ms just-in-time window on arrival: it goes at once), or dropped for time. Without the
    # adaptation every one would be sent with 398 ms, 408 ms before its deadline
    for t in after["DEMS-A"]:
        if t.tier == "cloud":
            assert t.notes["cloud_ms"] >= HV_STEPPED_MS - 10.0, (t.reason, t.notes)
            assert ("released to the cloud at once" in t.reason
                    or t.deadline_ms - t.notes["trigger_ms"] >= HV_STEPPED_MS), (t.reason, t.notes)
        else:
            est = float(re.search(r"cloud estimate (\d+) ms exceeds", t.reason).group(1))
            assert est >= HV_STEPPED_MS - 10.0, t.reason
    assert out["DEMS-A"][0].policy.cloud_estimate_ms("HV") >= HV_STEPPED_MS - 10.0
