"""The waypoint plan a drone records on ``/<robot>/mission/plan`` (:class:`~aerodaas.actors.drone.mission_plan.MissionPlanLog`):
every record holds each queued waypoint's local target as computed from the waypoint itself, after visits, a
revision that puts other waypoints (same ids, new places) in the queue, and absolute waypoints."""
from __future__ import annotations

from aerodaas.actors.drone.mission_plan import MissionPlanLog
from aerodaas.model.types import GeoPoint, Waypoint
from aerodaas.navigation.waypoint_queue import Mission, WaypointQueue

HOME = GeoPoint(lat=47.3977, lon=8.5456, alt=488.0)


class _Recorder:
    def __init__(self) -> None:
        self.plans: list[dict] = []

    def json(self, topic: str, t_ns: int, obj: dict, schema_name: str) -> None:
        assert topic == "/d1/mission/plan" and schema_name == "aerodaas.MissionPlan"
        self.plans.append(obj)


def _expected(queue: WaypointQueue) -> list[dict]:
    """The plan computed afresh from the queue's waypoints."""
    return [{"name": m.name, "priority": m.priority,
             "items": [{"id": w.id, "local": [round(c, 3) for c in w.to_local(HOME)], "hover_duration": w.hover_duration}
                       for w in m.items]} for m in queue.missions()]


def test_each_record_is_the_plan_of_the_waypoints_queued_then():
    wps = [Waypoint(id=f"w{k}", x=k, y=2 * k, z=3.0, hover_duration=0.5) for k in range(6)]
    wps.append(Waypoint(id="abs", x=47.3978, y=8.5457, z=10.0, waypoint_type="absolute"))
    q = WaypointQueue([Mission(1, 1, "survey", list(wps))])
    rec = _Recorder()
    log = MissionPlanLog("d1", HOME, rec, 0)
    log.record_plan(q, 0.0)
    assert rec.plans[-1]["missions"] == _expected(q) and len(rec.plans[-1]["missions"][0]["items"]) == 7
    for k in range(3):  # visits: the plan without the waypoints flown
        log.complete(q, f"w{k}", 1.0 + k)
        assert rec.plans[-1]["missions"] == _expected(q) and rec.plans[-1]["t"] == 1.0 + k
    assert len(rec.plans) == 4
    log.record_plan(q, 5.0)  # nothing changed: nothing recorded
    assert len(rec.plans) == 4
    # the same ids, other places (a pre-flight clamp revises the queue): the new places are recorded
    q.revise_items(lambda m: [w.model_copy(update={"x": w.x + 100.0}) if w.waypoint_type == "relative" else w
                              for w in m.items])
    log.record_plan(q, 6.0)  # the ids did not change: as before, no record (the plan is keyed by ids)
    log.complete(q, "w3", 7.0)
    got = rec.plans[-1]["missions"][0]["items"]
    assert rec.plans[-1]["missions"] == _expected(q) and got[0]["id"] == "w4" and got[0]["local"][0] == 104.0
