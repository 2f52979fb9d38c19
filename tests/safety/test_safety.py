"""SafetyGate (the choke point before the backend) and the simulator camera on the ground."""
from __future__ import annotations

import pytest

from aerodaas.config import RobotConfig
from aerodaas.model.types import AeroNavigation, VelocityCommand, Waypoint
from aerodaas.navigation.safety import SafetyGate, SafetyViolation

HOME = {"lat": 47.0, "lon": 8.0, "alt": 400.0}


def gate(**safety) -> SafetyGate:
    r = RobotConfig(id="r", home=HOME, limits={"max_speed": 3.0, "max_vertical_speed": 1.0}, safety=safety)
    return SafetyGate(r.safety, r.limits, r.home)


def test_altitude_and_speed_are_rejected_or_clamped():
    g = gate(max_altitude=20, min_altitude=1)
    with pytest.raises(SafetyViolation, match="max_altitude"):
        g.check_waypoint(Waypoint(id="a", x=0, y=0, z=25))
    with pytest.raises(SafetyViolation, match="min_altitude"):
        g.check_waypoint(Waypoint(id="b", x=0, y=0, z=0.5))
    with pytest.raises(SafetyViolation, match="max_speed"):
        g.check_velocity(VelocityCommand(vx=3, vy=3))
    c = gate(max_altitude=20, on_violation="clamp")
    assert c.check_waypoint(Waypoint(id="a", x=0, y=0, z=25)).z == 20
    v = c.check_velocity(VelocityCommand(vx=3, vy=4, vz=2))
    assert (v.vx, v.vy, v.vz) == pytest.approx((1.8, 2.4, 1.0))
    # a climb that would leave the envelope within the command's duration: vz zeroed when clamping
    assert c.check_velocity(VelocityCommand(vz=1.0, duration=2.0), position=(0, 0, 19.5)).vz == 0.0
    assert c.stats()["clamped"] == 3 and g.stats()["rejected"] == 3


def test_geofence_exclusion_zone_blocks_points_legs_and_velocity():
    excl = {"circles": [{"center": [47.0, 8.0002], "radius": 5.0, "inclusion": False}]}  # ~15 m east of home
    g = gate(geofence=excl)
    east = 0.0002 * 111320 * 0.682  # metres east of home of the circle centre (cos 47 deg)
    with pytest.raises(SafetyViolation, match="geofence"):
        g.check_waypoint(Waypoint(id="in", x=east, y=0, z=2))
    # both ends outside the circle, but the leg crosses it
    with pytest.raises(SafetyViolation, match="geofence"):
        g.check_waypoint(Waypoint(id="past", x=2 * east, y=0, z=2), from_position=(0, 0, 2))
    assert g.check_waypoint(Waypoint(id="north", x=0, y=30, z=2), from_position=(0, 0, 2)).id == "north"
    with pytest.raises(SafetyViolation, match="geofence"):
        g.check_velocity(VelocityCommand(vx=2.0, duration=10.0), position=(0, 0, 2))
    # all or nothing: one bad item rejects the whole navigation
    nav = AeroNavigation(waypoints=[Waypoint(id="ok", x=0, y=10, z=2), Waypoint(id="bad", x=east, y=0, z=2)])
    with pytest.raises(SafetyViolation, match="bad"):
        g.check_navigation(nav, (0, 0, 2))


def test_camera_on_the_ground_renders():
    """A landed drone (camera height 0) must not make the ground homography singular."""
    from aerodaas.config import GroundConfig
    from aerodaas.model.types import CameraIntrinsics, FramePose
    from aerodaas.sim.world import World

    w = World(GroundConfig(seed=1, size_m=20), [])
    k = CameraIntrinsics.from_hfov(64, 48, 78)
    for z in (0.0, -0.01):
        frame, _ = w.render(FramePose(position=(0.0, 0.0, z)), k, 0.0)
        assert frame.shape == (48, 64, 3)
