"""The analytics scheduler's task counts from the recording: the recorder tallies the task records
it writes per scheduler into ``/run/accounting``, across its segments, and the summary's scheduler headline is
that tally; the dispatchers' own count (it restarts with their actor) is shown only where it differs. In process,
on fabricated task records."""
from __future__ import annotations

import pytest

from aerodaas.actors.recording.recorder import RecorderService
from aerodaas.recording.accounting import account_recording
from aerodaas.recording.task_tally import TASK_SCHEMA, TaskCounts, TaskTally, tally_recordings
from aerodaas.runtime.report import _scheduler_lines


def _record(k: int, state: str, tier: str | None, utility: float, cost: float, scheduler: str = "DEMS") -> dict:
    return {"task_id": k, "model": "detector", "state": state, "tier": tier, "reason": "", "arrival_ms": 10.0 * k,
            "deadline_ms": 10.0 * k + 300, "start_ms": None, "end_ms": None, "utility": utility, "cost": cost,
            "scheduler": scheduler}


#: 3 on time (2 edge at cost 1, 1 cloud at cost 20), 1 late on the cloud, 2 dropped, 1 failed on the edge
RECORDS = [_record(1, "done_on_time", "edge", 99, 1), _record(2, "done_on_time", "edge", 99, 1),
           _record(3, "done_on_time", "cloud", 80, 20), _record(4, "done_late", "cloud", -20, 20),
           _record(5, "dropped_time", None, 0, 0), _record(6, "dropped_cost", None, 0, 0),
           _record(7, "failed", "edge", -1, 1)]


def test_the_tally_counts_states_tiers_utility_and_cost_per_scheduler():
    t = TaskTally().add_all(RECORDS + [_record(8, "done_on_time", "edge", 99, 1, scheduler="GEMS")])
    d = t.as_dict()
    assert set(d) == {"DEMS", "GEMS"}
    dems = d["DEMS"]
    assert dems["tasks"] == 7 and dems["on_time"] == 3
    assert dems["states"] == {"done_late": 1, "done_on_time": 3, "dropped_cost": 1, "dropped_time": 1, "failed": 1}
    assert dems["tiers"] == {"cloud": 2, "edge": 3, "none": 2}
    assert dems["utility"] == pytest.approx(99 + 99 + 80 - 20 - 1)
    assert dems["cost"] == pytest.approx(43) and dems["cost_by_tier"] == {"cloud": 40.0, "edge": 3.0, "none": 0.0}
    # JSON round trip and sums (a recorder's segments)
    assert TaskTally.from_dict(d).as_dict() == d
    twice = t.merged(TaskTally.from_dict(d)).as_dict()
    assert twice["DEMS"]["tasks"] == 14 and twice["DEMS"]["states"]["done_on_time"] == 6
    assert twice["GEMS"]["utility"] == pytest.approx(198)
    assert TaskCounts().merged(TaskCounts.from_dict(dems)).as_dict() == dems


def test_the_recorder_writes_the_tally_of_every_segment_into_the_accounting(tmp_path):
    """Two segments (the recorder actor died once): the second's accounting tallies the task records of both, read
    from the first one's file the way its message counts are."""
    a, b = tmp_path / "run.mcap", tmp_path / "run.1.mcap"
    first = RecorderService(str(a), flush_every_s=0.0)
    for k, r in enumerate(RECORDS[:3]):
        first.json("/d1/detector/tasks", k + 1, r, TASK_SCHEMA, seq=k)
    first.close()
    second = RecorderService(str(b), flush_every_s=0.0)
    for k, r in enumerate(RECORDS[3:], start=3):
        second.json("/d1/detector/tasks", k + 1, r, TASK_SCHEMA, seq=k)
    second.json("/d1/other", 9, {"state": "failed"}, "t.Other", seq=0)  # not a task record
    before = tally_recordings([a])
    assert before.as_dict()["DEMS"]["tasks"] == 3
    second.close(recorded_before={"/d1/detector/tasks": 3}, tasks_before=before)
    acc = account_recording([a, b])
    assert acc["tasks"] == TaskTally().add_all(RECORDS).as_dict()
    assert tally_recordings([a, b]).as_dict() == acc["tasks"]
    assert tally_recordings([tmp_path / "gone.mcap"]).as_dict() == {}  # unreadable: nothing to count


SR = {"scheduler": "DEMS", "submitted": 4, "on_time_rate": 0.5, "tiers": {"edge": 2, "cloud": 1},
      "utility": 150.0, "cloud_cost": 20.0, "states": {"done_on_time": 2, "dropped_time": 2}}


def test_the_summary_headline_is_the_recordings_and_names_the_dispatchers_count_when_it_differs():
    acc = {"channels": {"/d1/detector/tasks": {"recorded": 7}}, "tasks": TaskTally().add_all(RECORDS).as_dict()}
    line = _scheduler_lines(SR, acc)[0]
    assert line == ("  analytics scheduler DEMS: 7 tasks (from the recording), on time 42.9% (edge 3, cloud 2), "
                    "utility 257, cloud cost 40; done_on_time 3, done_late 1, dropped_time 1, dropped_cost 1, "
                    "failed 1; its dispatchers counted 4 (since their last restart)")
    same = _scheduler_lines({**SR, "submitted": 7}, acc)[0]
    assert same.endswith("failed 1")  # the dispatchers agree: nothing more said
    more = _scheduler_lines({**SR, "submitted": 9}, acc)[0]
    assert more.endswith("its dispatchers counted 9 (2 more than the recording holds: task records lost)")
    gone = _scheduler_lines(None, acc)[0]  # the dispatcher's actor did not answer at the end
    assert "7 tasks (from the recording)" in gone and gone.endswith("its dispatchers did not report")


def test_without_a_tally_the_summary_headline_is_the_dispatchers():
    assert _scheduler_lines(SR, {}) == [
        "  analytics scheduler DEMS: 4 tasks, on time 50.0% (edge 2, cloud 1), utility 150, cloud cost 20; "
        "done_on_time 2, dropped_time 2"]
    with_file = _scheduler_lines(SR, {"channels": {"/d1/detector/tasks": {"recorded": 4}}})[0]
    assert with_file.endswith("; 4 task records in the recording")
    assert _scheduler_lines(None, {}) == [] and _scheduler_lines(None, {"tasks": {}}) == []
    # a recording without task records while the dispatchers ran some: the recording's 0, and theirs
    none = _scheduler_lines(SR, {"channels": {}, "tasks": {}})[0]
    assert none.startswith("  analytics scheduler DEMS: 0 tasks (from the recording)")
    assert none.endswith("its dispatchers counted 4 (4 more than the recording holds: task records lost)")
