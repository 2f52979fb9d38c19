import math

import numpy as np
import pytest

from aerodaas.config import BatteryConfig, GroundConfig, Limits
from aerodaas.model.types import (AeroNavigation, CameraIntrinsics, FramePose, GeoPoint, NavigationType, PriorityQueue,
                             SchedulingType, VelocityCommand, Waypoint)
from aerodaas.schedulers import NearestNeighborScheduler, TrajectoryScheduler
from aerodaas.sim.vehicle import SimVehicle
from aerodaas.model.camera import pixel_to_ground, project_points
from aerodaas.sim.world import World


def wp(i, x, y, z=2.0, **kw):
    return Waypoint(id=f"w{i}", x=x, y=y, z=z, **kw)


def test_nearest_neighbor_orders_greedily_and_shortens_the_tour():
    pts = [wp(1, 10, 10), wp(2, 0, 1), wp(3, 10, 0), wp(4, 0, 10)]
    s = NearestNeighborScheduler()
    nav = s.generate_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, pts, SchedulingType.UNORDERED))
    assert [w.id for w in nav.waypoints] == ["w2", "w4", "w1", "w3"]
    assert s.tour_length(nav.waypoints, (0, 0, 0)) < s.tour_length(pts, (0, 0, 0))
    ordered = TrajectoryScheduler().generate_navigation(AeroNavigation(waypoints=pts))
    assert [w.id for w in ordered.waypoints] == ["w1", "w2", "w3", "w4"]


def test_priority_preemption_resumes_where_it_left_off_and_clear_aborts():
    s = TrajectoryScheduler()
    s.generate_navigation(PriorityQueue(AeroNavigation(waypoints=[wp(1, 0, 0), wp(2, 5, 0), wp(3, 9, 0)]), priority=2))
    assert s.current(0.0)[1].id == "w1"
    assert s.complete("w1")
    # a priority-1 follow mission preempts the survey
    s.add_navigation(PriorityQueue(AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [VelocityCommand(vx=1, duration=0.5)]), 1))
    m, item = s.current(1.0)
    assert m.priority == 1 and isinstance(item, VelocityCommand)
    # once the command expires the survey resumes at w2, not w1 or w3
    assert s.current(1.6)[1].id == "w2"
    s.add_navigation([wp(9, 1, 1)], index=0, priority=2)
    assert s.current(1.7)[1].id == "w9"
    s.clear_navigation()
    assert s.current(2.0) is None and s.pending() == 0


def test_unordered_additions_replan_from_the_drone_position():
    s = NearestNeighborScheduler()
    s.generate_navigation(AeroNavigation(waypoints=[wp(1, 0, 0)]))
    s.add_navigation(AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [wp(2, 20, 0), wp(3, 2, 0)],
                                    SchedulingType.UNORDERED), priority=2, position=(0, 0, 2))
    assert [i.id for i in s.queue.entries[0].items] == ["w1", "w3", "w2"]


def test_vehicle_respects_limits_reaches_target_and_drains_battery():
    lim = Limits(max_speed=2.0, max_vertical_speed=1.0, max_acceleration=1.0)
    v = SimVehicle("d", GeoPoint(lat=47, lon=8, alt=400), lim, BatteryConfig())
    v.arm()
    v.takeoff(5.0)
    vmax = 0.0
    for _ in range(50 * 10):
        v.step(0.02)
        vmax = max(vmax, abs(v.state.velocity[2]))
    assert v.state.position[2] == pytest.approx(5.0, abs=0.05) and vmax <= 1.0 + 1e-9
    v.goto((30.0, 0.0, 5.0))
    speeds = []
    for _ in range(50 * 25):
        v.step(0.02)
        speeds.append(math.hypot(*v.state.velocity[:2]))
    assert math.dist(v.state.position, (30, 0, 5)) < 0.05
    assert max(speeds) <= 2.0 + 1e-9 and np.max(np.abs(np.diff(speeds))) <= 1.0 * 0.02 + 1e-9
    odo = v.odometry()
    assert odo.battery_pct < 100.0 and odo.geodetic.lat == pytest.approx(47.0, abs=1e-5)
    assert odo.geodetic.lon > 8.0  # 30 m east


def test_camera_geometry_projects_and_back_projects():
    k = CameraIntrinsics.from_hfov(640, 480, 78)
    pose = FramePose(position=(3.0, -2.0, 12.0), yaw=90.0, camera_pitch=90.0)
    uv, front = project_points(np.array([[3.0, -2.0, 0.0], [5.0, -2.0, 0.0], [3.0, 0.0, 0.0]]), pose, k)
    assert front.all()
    assert uv[0] == pytest.approx([320, 240])
    assert uv[1][0] > 320 and uv[1][1] == pytest.approx(240)  # east is image right when facing north
    assert uv[2][1] < 240  # north is image up
    g = pixel_to_ground(uv[1][0], uv[1][1], pose, k)
    assert g == pytest.approx((5.0, -2.0), abs=1e-6)
    pitched = FramePose(position=(0.0, 0.0, 10.0), yaw=90.0, camera_pitch=30.0)
    assert pixel_to_ground(320, 0, pitched, k) is None  # above the horizon


def test_procedural_ground_renders_and_moves_with_the_drone():
    w = World(GroundConfig(seed=1, metres_per_pixel=0.05, size_m=40), [])
    k = CameraIntrinsics.from_hfov(160, 120, 78)
    a, _ = w.render(FramePose(position=(0, 0, 5), yaw=90), k, 0.0)
    b, _ = w.render(FramePose(position=(0, 0, 5), yaw=90), k, 1.0)
    c, _ = w.render(FramePose(position=(4, 0, 5), yaw=90), k, 1.0)
    assert a.shape == (120, 160, 3) and a.dtype == np.uint8
    assert np.array_equal(a, b) and np.abs(a.astype(int) - c.astype(int)).mean() > 5
