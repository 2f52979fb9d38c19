"""The vertical limit holds at every allowed physics step: ``physics_hz`` 10 with a waypoint at 9.95 m
under ``max_altitude`` 10 climbed to 10.094 m; with fast climbs and a turn sharing the acceleration the simulator
passed a waypoint by up to 0.8-1.0 m. Now a position target is approached with the discrete-time braking speed
and the vertical change first (aerodaas.navigation.braking), in the simulator and in the gate's prediction alike:
the vehicle never passes the altitude of its target, at any step the configuration allows."""
from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st

from aerodaas.model.types import GeoPoint
from aerodaas.config import BatteryConfig, Limits
from aerodaas.model.bounds import MIN_PHYSICS_HZ
from aerodaas.navigation.braking import braking_speed, limited_change
from aerodaas.sim.vehicle import SimVehicle

HOME = GeoPoint(lat=47.0, lon=8.0, alt=0.0)


def _fly(limits: Limits, start_z: float, target: tuple[float, float, float], dt: float, seconds: float) -> list:
    """Altitudes (m) at every step of a vehicle hovering at ``start_z`` over home and sent to ``target``, until it
    has settled there (or ``seconds`` ran out)."""
    v = SimVehicle("d", HOME, limits, BatteryConfig(capacity_wh=1000.0))
    v.arm()
    v.state.position[2], v.state.in_air = start_z, True  # hovering (the take-off is the same position law)
    v.goto(target)
    zs = []
    for _ in range(int(seconds / dt)):
        v.step(dt)
        zs.append(float(v.state.position[2]))
        if abs(zs[-1] - target[2]) < 1e-6 and float(abs(v.state.velocity).max()) < 1e-6:
            break
    return zs


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(vz=st.floats(0.2, 10.0), accel=st.floats(0.3, 20.0), vh=st.floats(0.5, 20.0),
       hz=st.sampled_from([MIN_PHYSICS_HZ, 12.5, 20.0, 50.0, 100.0]),
       start_z=st.floats(1.0, 5.0), climb=st.floats(0.05, 30.0), east=st.floats(-60.0, 60.0))
def test_a_climb_to_a_waypoint_never_passes_its_altitude(vz, accel, vh, hz, start_z, climb, east):
    """From its odometry at every physics step: never above the target's altitude (to float rounding)."""
    limits = Limits(max_speed=vh, max_vertical_speed=vz, max_acceleration=accel)
    target_z = start_z + climb
    zs = _fly(limits, start_z, (east, 0.5 * east, target_z), 1.0 / hz, seconds=climb / vz + abs(east) / vh + 20.0)
    assert max(zs) <= target_z + 1e-9, (max(zs) - target_z)


@pytest.mark.parametrize("hz", [10.0, 50.0])
def test_a_waypoint_5cm_under_the_ceiling_stays_under_it(hz):
    """A waypoint 9.95 m under a 10 m ceiling at 10 Hz (10.094 m before), with the acceleration and climb
    rate that overshot most in a sweep (1.04 m before)."""
    for limits in (Limits(max_speed=3.0, max_vertical_speed=1.5, max_acceleration=2.0),
                   Limits(max_speed=10.0, max_vertical_speed=10.0, max_acceleration=5.0),
                   Limits(max_speed=3.0, max_vertical_speed=3.0, max_acceleration=0.5)):
        zs = _fly(limits, 2.0, (30.0, 0.0, 9.95), 1.0 / hz, seconds=90.0)
        assert max(zs) <= 9.95 + 1e-9 and max(zs) > 9.95 - 1e-6, (limits, max(zs))  # arrived, never above


def test_braking_speed_is_the_discrete_stopping_bound():
    """From ``braking_speed(d)`` a stepping vehicle braking at ``a`` stops within ``d``; from a little more it does
    not; it lies under the continuous ``sqrt(2 a d)`` and under ``d / dt``."""
    for d, a, dt in ((0.05, 2.0, 0.1), (1.0, 5.0, 0.1), (7.95, 0.5, 0.02), (30.0, 20.0, 0.001)):
        v = braking_speed(d, a, dt)
        assert v <= (2 * a * d) ** 0.5 and v * dt <= d + 1e-12

        def travel(v0: float) -> float:
            x, u = 0.0, v0
            x += u * dt  # the step flown at v0
            while u > 0:
                u = max(0.0, u - a * dt)
                x += u * dt
            return x

        assert travel(v) <= d + 1e-9
        assert travel(v * 1.05 + a * dt) > d
    assert braking_speed(0.0, 2.0, 0.1) == 0.0


def test_the_vertical_change_comes_first_within_one_budget():
    got = limited_change([3.0, 4.0, -2.0], 1.0, vertical_first=True)
    assert got[2] == -1.0 and abs(got[0]) < 1e-12 and abs(got[1]) < 1e-12
    got = limited_change([3.0, 4.0, 0.6], 1.0, vertical_first=True)
    assert got[2] == 0.6 and abs((got[0] ** 2 + got[1] ** 2 + got[2] ** 2) ** 0.5 - 1.0) < 1e-12
    got = limited_change([3.0, 4.0, 0.0], 1.0)  # one budget along the change
    assert abs(got[0] - 0.6) < 1e-12 and abs(got[1] - 0.8) < 1e-12
