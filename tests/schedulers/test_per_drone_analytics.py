"""Per-drone state in shared analytics: one analytics object fed by several drones keeps what it remembers
(follow tracks, PID integrators, confirmation streaks, minima/maxima) per drone, keyed by the robot id the items
carry; and the analytics API's ``process_batch`` (default: one ``process`` call per item).

The analytics are called directly here, as the runtime calls them; tests/perception/test_fleet_follow.py flies the same through
the runtime."""
from __future__ import annotations

import numpy as np
import pytest

from aerodaas import Analytics, FollowAnalytics, MonitoringAnalytics
from aerodaas.analytics.core import source_robot
from aerodaas.analytics.extra import FallDetector, InspectionPlanner
from aerodaas.model.types import ActionCommand, CameraIntrinsics, Detection, FrameMeta, FramePose, VelocityCommand
from aerodaas.model.camera import project_points

K = CameraIntrinsics.from_hfov(640, 480, 78.0)


def _meta(robot: str, seq: int, t: float, pos: tuple[float, float, float]) -> FrameMeta:
    return FrameMeta(robot_id=robot, sensor_id="cam", seq=seq, capture_time=t, wall_time=0.0,
                     pose=FramePose(position=pos, yaw=90.0, camera_pitch=90.0), intrinsics=K)


def _seen(meta: FrameMeta, cls: str, xy: tuple[float, float], half_px: float = 8.0) -> list[Detection]:
    """The detection a perfect detector reports for an object at ground ENU ``xy`` (metres) in this frame."""
    uv, front = project_points(np.array([[xy[0], xy[1], 0.0]]), meta.pose, meta.intrinsics)
    u, v = uv[0]
    assert front[0] and 0 < u < K.width and 0 < v < K.height, "the test puts every target in view"
    return [Detection(class_id=2, class_name=cls, score=0.9, box=(u - half_px, v - half_px, u + half_px, v + half_px))]


# two drones 60 m apart, each above its own car; the cars drive in different directions (m/s)
DRONES = {"d1": (0.0, 0.0, 10.0), "d2": (60.0, 0.0, 10.0)}
CARS = {"d1": ((3.0, 2.0), (1.0, 0.0)), "d2": ((57.0, -3.0), (0.0, -1.0))}


def _car(robot: str, t: float) -> tuple[float, float]:
    (x, y), (vx, vy) = CARS[robot]
    return (x + vx * t, y + vy * t)


def _frames(robot: str, n: int = 15, dt: float = 0.1) -> list[tuple[list[Detection], FrameMeta]]:
    out = []
    for i in range(n):
        m = _meta(robot, i, i * dt, DRONES[robot])
        out.append((_seen(m, "car", _car(robot, m.capture_time)), m))
    return out


def _velocity(nav) -> np.ndarray:
    (cmd,) = nav.waypoints
    assert isinstance(cmd, VelocityCommand)
    return np.array([cmd.vx, cmd.vy])


def test_source_robot_names_the_drone_of_every_item_kind():
    m = _meta("d7", 0, 0.0, (0.0, 0.0, 5.0))
    assert source_robot(np.zeros((2, 2, 3), np.uint8), m) == "d7"  # a frame: its FrameMeta
    assert source_robot([], m) == "d7"  # detections travel with their frame's FrameMeta
    assert source_robot({"robot_id": "d3", "t": 1.0}, None) == "d3"  # odometry
    assert source_robot({"robot": "d4", "state": "HOVERING"}, None) == "d4"  # a stat-stream message
    assert source_robot(42.0, None) == ""  # an environment sensor's value: no drone


def test_shared_follow_keeps_a_track_and_a_controller_per_drone():
    """Two drones interleave frames into one FollowAnalytics, each seeing its own car: each keeps its own track
    (at its own car), and each drone's commands are exactly those a FollowAnalytics of its own would give."""
    shared = FollowAnalytics(target_classes=["car"], confirm_hits=2)
    solo = {r: FollowAnalytics(target_classes=["car"], confirm_hits=2) for r in DRONES}
    frames = {r: _frames(r) for r in DRONES}
    got = {r: [] for r in DRONES}
    want = {r: [] for r in DRONES}
    for i in range(15):
        for r in DRONES:  # d1, d2, d1, d2, ...
            dets, meta = frames[r][i]
            got[r].append(shared.process(dets, meta))
            want[r].append(solo[r].process(dets, meta))
    for r in DRONES:
        navs = [n for n in got[r] if n is not None]
        assert len(navs) == 15 - 1  # confirmed on its second frame, then a command on every frame
        for a, b in zip(got[r], want[r]):
            assert (a is None) == (b is None)
            if a is not None:
                np.testing.assert_allclose(_velocity(a), _velocity(b))  # same PID memory as a drone of its own
        tr = shared.track_of(r)
        car_now = np.array(_car(r, 1.4))
        assert np.linalg.norm(tr.track - car_now) < 0.5, (r, tr.track, car_now)  # locked on its own car
        np.testing.assert_allclose(tr.track_v, CARS[r][1], atol=0.2)  # and on that car's velocity
    # each drone is sent towards its own car: d1's car is north-east of it, moving east; d2's south-west, moving south
    v1, v2 = _velocity(got["d1"][-1]), _velocity(got["d2"][-1])
    assert v1[0] > 0.5 and v1[1] > 0.5
    assert v2[0] < -0.5 and v2[1] < -0.5
    assert shared.stats()["commands_by_drone"] == {"d1": 14, "d2": 14}
    assert shared.stats()["commands"] == 28


def test_one_drone_losing_its_target_does_not_drop_the_other_drones_track():
    follow = FollowAnalytics(target_classes=["car"], confirm_hits=1, lost_after=0.5)
    for i in range(5):
        for r in DRONES:
            follow.process(*_frames(r, n=5)[i])
    # d1's car leaves: 1 s of empty frames for d1 (> lost_after); d2 still sees its car
    for i in range(5, 15):
        t = i * 0.1
        follow.process([], _meta("d1", i, t, DRONES["d1"]))
        m2 = _meta("d2", i, t, DRONES["d2"])
        assert follow.process(_seen(m2, "car", _car("d2", t)), m2) is not None
    assert follow.track_of("d1").track is None  # d1's track dropped
    assert follow.track_of("d2").track is not None and follow.track_of("d2").hits == 15


def test_shared_monitor_keeps_minima_and_maxima_per_drone():
    mon = MonitoringAnalytics(["battery", "height"], limits={"battery": 50})
    for t, (b1, b2) in enumerate([(90, 40), (80, 45), (85, 60)]):
        for r, b, z in (("d1", b1, 10.0 + t), ("d2", b2, 3.0)):
            out = mon.process({"robot_id": r, "t": float(t), "battery_pct": b, "position": [0, 0, z],
                               "velocity": [0, 0, 0], "geodetic": {"lat": 0, "lon": 0, "alt": 0}}, None)
            assert out["robot"] == r
    st = mon.stats()
    assert st["by_drone"]["d1"]["battery"] == {"min": 80, "max": 90}
    assert st["by_drone"]["d2"]["battery"] == {"min": 40, "max": 60}
    assert st["by_drone"]["d1"]["height"] == {"min": 10.0, "max": 12.0}
    assert st["summary"]["battery"] == {"min": 40, "max": 90}  # over the fleet
    assert len(st["warnings"]) == 2 and all(w.startswith("d2: battery") for w in st["warnings"])


class _ScriptedFall(FallDetector):
    """The emergency-pose analytics with its ONNX inference replaced by a script: a frame whose first pixel is 255
    shows a fall (the per-drone logic under test is the analytics' own)."""

    def setup(self) -> None:
        pass

    def infer(self, frame):
        score = 0.9 if frame[0, 0, 0] == 255 else 0.1
        return [Detection(class_id=1, class_name="Fall", score=score, box=(0, 0, 1, 1))]


def test_shared_fall_detector_counts_streaks_per_drone_and_lands_only_that_drone():
    fall = _ScriptedFall(confirm_frames=3)
    fallen = np.full((4, 4, 3), 255, np.uint8)
    fine = np.zeros((4, 4, 3), np.uint8)
    outs = {"d1": [], "d2": []}
    for i in range(4):  # d1 sees a fall on every frame; d2's frames alternate (its streak never reaches 3)
        outs["d1"].append(fall.process(fallen, _meta("d1", i, 0.1 * i, DRONES["d1"])))
        outs["d2"].append(fall.process(fallen if i % 2 == 0 else fine, _meta("d2", i, 0.1 * i, DRONES["d2"])))
    assert outs["d1"][:2] == [None, None] and outs["d1"][3] is None  # fires once, on its third fall frame
    (cmd,) = outs["d1"][2].waypoints
    assert isinstance(cmd, ActionCommand) and cmd.action == "land"
    assert outs["d2"] == [None] * 4  # interleaved d1 falls do not complete d2's streak
    st = fall.stats()
    assert st["landing_commanded_to"] == ["d1"] and st["frames"] == 8 and st["processed"] == 7


def test_shared_inspection_planner_plans_around_each_drones_own_structure():
    planner = InspectionPlanner(base_altitude=5, top_altitude=5, step_m=5, radius_m=2, faces=4, confirm_hits=2)
    where = {"d1": (2.0, 1.0), "d2": (58.0, 1.0)}
    plans = {}
    for i in range(3):
        for r in DRONES:
            m = _meta(r, i, 0.1 * i, DRONES[r])
            dets = [d.model_copy(update={"class_name": "structure"}) for d in _seen(m, "car", where[r])]
            nav = planner.process(dets if (r == "d1" or i > 0) else [], m)
            if nav is not None:
                plans[r] = nav
    assert set(plans) == {"d1", "d2"}
    for r, nav in plans.items():
        np.testing.assert_allclose(planner.planned_for(r), where[r], atol=0.05)
        centre = np.mean([(w.x, w.y) for w in nav.waypoints if not isinstance(w, ActionCommand)], axis=0)
        np.testing.assert_allclose(centre, where[r], atol=0.05)


class _Doubler(Analytics):
    def __init__(self):
        super().__init__("doubler")
        self.calls = 0

    def process(self, data, meta):
        self.calls += 1
        return None if data is None else 2 * data


def test_process_batch_defaults_to_one_process_call_per_item_in_order():
    a = _Doubler()
    assert a.max_batch == 1
    assert a.process_batch([(1, None), (None, None), (5, None)]) == [2, None, 10]
    assert a.calls == 3
    assert a.process_batch([]) == []


def test_follow_through_process_batch_equals_item_by_item():
    batched, single = FollowAnalytics(target_classes=["car"]), FollowAnalytics(target_classes=["car"])
    f1, f2 = _frames("d1", n=6), _frames("d2", n=6)
    for i in range(6):
        items = [f1[i], f2[i]]  # one frame of each drone per batch
        got = batched.process_batch(items)
        want = [single.process(d, m) for d, m in items]
        assert [g is None for g in got] == [w is None for w in want]
        for g, w in zip(got, want):
            if g is not None:
                np.testing.assert_allclose(_velocity(g), _velocity(w))


@pytest.mark.parametrize("cls", [FollowAnalytics, MonitoringAnalytics, InspectionPlanner])
def test_stateful_analytics_say_so_for_replica_routing(cls):
    assert cls().stateful is True


@pytest.mark.parametrize("interval_s,latency_s", [(0.1, 0.05), (0.4, 0.35), (0.6, 0.55)])
def test_a_slow_detectors_follow_commands_leave_no_gap_for_the_preempted_survey(interval_s, latency_s):
    """A detector that analyses one frame every ``interval_s`` (vehicle s) and answers ``latency_s`` after its
    capture (at 4x real time an 80-140 ms inference is 0.32-0.56 s): from the second command on, the drone's
    scheduler always has a live follow command at priority 1, so the survey at priority 2 never takes over between
    two detections (it did with 0.5 s commands: TRACKING and NAVIGATING alternated every 0.1-0.4 s)."""
    from schedulers.base import TrajectoryScheduler

    from aerodaas.model.types import AeroNavigation, NavigationType, PriorityQueue, Waypoint

    follow = FollowAnalytics(target_classes=["car"], confirm_hits=1)
    sched = TrajectoryScheduler()
    survey = AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="s", x=50, y=0, z=10)])
    sched.add_navigation(PriorityQueue(survey, priority=2))
    arrivals = []
    for k in range(8):
        m = _meta("d1", k, k * interval_s, DRONES["d1"])
        nav = follow.process(_seen(m, "car", _car("d1", m.capture_time)), m)
        assert nav is not None
        arrivals.append((m.capture_time + latency_s, nav))
    heads = []
    t, dt = arrivals[1][0], 0.01  # the drone's ticks from the second command's arrival
    while t < arrivals[-1][0]:
        while arrivals and arrivals[0][0] <= t:
            sched.add_navigation(arrivals.pop(0)[1], priority=1)
        mission, item = sched.current(t)
        heads.append((round(t, 2), mission.priority))
        t += dt
    assert all(p == 1 for _, p in heads), [h for h in heads if h[1] != 1][:5]
    d = follow.duration_for(follow.track_of("d1"))
    assert follow.command_duration < d <= 4 * follow.command_duration


def test_a_pause_in_the_frames_does_not_stretch_follow_commands_beyond_four_command_durations():
    """A detector restart (60 s without frames) with ``lost_after`` effectively infinite (as the benchmarks set it):
    the next command still lasts at most 4 x ``command_duration``."""
    follow = FollowAnalytics(target_classes=["car"], confirm_hits=1, lost_after=1e9)
    for k, t in enumerate([0.0, 0.1, 0.2, 60.2, 60.3]):
        m = _meta("d1", k, t, DRONES["d1"])
        nav = follow.process(_seen(m, "car", _car("d1", 0.0)), m)
    (cmd,) = nav.waypoints
    assert cmd.duration <= 4 * follow.command_duration
    assert cmd.issued_at == 60.3


def test_a_velocity_command_is_checked_for_the_time_it_has_left():
    """The drone re-checks its current velocity command every tick: for the seconds still left of it, so a long
    command near a fence is not refused for flight it will never make."""
    c = VelocityCommand(vx=1.0, duration=2.0, issued_at=10.0)
    assert c.left_at(10.0) is c and c.left_at(9.0) is c
    assert c.left_at(11.5).duration == pytest.approx(0.5)
    assert c.left_at(13.0).duration == pytest.approx(1e-3)  # ran out: the least the model allows
    assert VelocityCommand(vx=1.0).left_at(99.0).duration == 0.5  # never issued: the whole command
