"""The gimbal's geometry and MAVLink gimbal/camera protocol v2 pieces (development tier). The firmware's side is
tests/firmware/test_sitl_gimbal.py; here the conventions are tied to the simulator's camera model (the optical axis of a
camera posed by :func:`camera_angles` after :func:`roi_angles` passes through the region of interest) and the
messages are real MAVLink bytes packed and parsed by pymavlink."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError
from pymavlink.dialects.v20 import common as mav

from aerodaas.backends.mavlink.gimbal import GimbalManager
from aerodaas.model.camera import camera_rotation
from aerodaas.navigation.gimbal import (
    GimbalLimits,
    GimbalModel,
    camera_angles,
    euler_from_quaternion,
    quaternion_from_euler,
    roi_angles,
    wrap_deg,
)

finite = st.floats(-500, 500, allow_nan=False)


def _wire(msg, src_component=1):
    """``msg`` packed to MAVLink 2 bytes by one endpoint and parsed back by another (as a link delivers it)."""
    out = mav.MAVLink(None, srcSystem=1, srcComponent=src_component)
    return mav.MAVLink(None).parse_char(bytearray(msg.pack(out)))


@settings(max_examples=200, deadline=None)
@given(roll=st.floats(-179, 179), pitch=st.floats(-89, 89), yaw=st.floats(-179, 179))
def test_quaternion_round_trip(roll, pitch, yaw):
    r, p, y = euler_from_quaternion(quaternion_from_euler(roll, pitch, yaw))
    assert r == pytest.approx(roll, abs=1e-6) and p == pytest.approx(pitch, abs=1e-6) and \
        wrap_deg(y - yaw) == pytest.approx(0, abs=1e-6)


@settings(max_examples=300, deadline=None)
@given(vx=finite, vy=finite, vz=st.floats(1, 120), yaw=st.floats(-180, 180), rx=finite, ry=finite,
       rz=st.floats(-50, 0))
def test_the_camera_pointed_by_roi_angles_looks_at_the_point(vx, vy, vz, yaw, rx, ry, rz):
    if math.hypot(rx - vx, ry - vy) < 0.01:
        return
    pitch, gyaw = roi_angles((vx, vy, vz), yaw, (rx, ry, rz))
    cam_yaw, cam_pitch = camera_angles(yaw, pitch, gyaw)
    axis = camera_rotation(cam_yaw, cam_pitch)[2]  # the simulator's optical axis in ENU
    d = np.array([rx - vx, ry - vy, rz - vz])
    assert axis @ d / np.linalg.norm(d) == pytest.approx(1.0, abs=1e-9)


def test_roi_angles_by_hand():
    north = 90.0  # ENU yaw of a vehicle whose nose points north
    assert roi_angles((0, 0, 10), north, (0, 10, 0)) == pytest.approx((-45.0, 0.0))
    assert roi_angles((0, 0, 10), north, (10, 0, 10)) == pytest.approx((0.0, 90.0))  # east: to the right
    assert roi_angles((0, 0, 10), north, (-10, 0, 10)) == pytest.approx((0.0, -90.0))
    assert roi_angles((5, 5, 30), 0.0, (5, 5, 0)) == pytest.approx((-90.0, 0.0))  # straight below
    with pytest.raises(ValueError, match="finite"):
        roi_angles((0, 0, math.nan), 0.0, (1, 1, 0))


def test_limits_are_strict_and_ordered():
    with pytest.raises(ValidationError, match="pitch_min_deg"):
        GimbalLimits(pitch_min_deg="-90")
    with pytest.raises(ValidationError, match="rate_deg_s"):
        GimbalLimits(rate_deg_s=True)
    with pytest.raises(ValidationError, match="must be below"):
        GimbalLimits(pitch_min_deg=10, pitch_max_deg=-10)
    lim = GimbalLimits()
    with pytest.raises(ValueError, match="pitch_deg -91"):
        lim.check(-91, 0)
    with pytest.raises(ValueError, match="yaw_deg nan"):
        lim.check(0, math.nan)
    assert lim.clamp(-120, 190) == (-90.0, -170.0)


@settings(max_examples=100, deadline=None)
@given(p0=st.floats(-90, 20), y0=st.floats(-180, 179), p1=st.floats(-90, 20), y1=st.floats(-180, 179),
       dt=st.floats(0.01, 0.5))
def test_the_model_slews_at_its_rate_and_arrives(p0, y0, p1, y1, dt):
    g = GimbalModel(GimbalLimits(rate_deg_s=45.0), p0, y0)
    g.point(p1, y1)
    for _ in range(1000):
        before = (g.pitch_deg, g.yaw_deg)
        g.step(dt)
        assert abs(g.pitch_deg - before[0]) <= 45.0 * dt + 1e-9
        assert abs(wrap_deg(g.yaw_deg - before[1])) <= 45.0 * dt + 1e-9  # the shorter way round
        if g.settled:
            break
    assert g.settled


def test_the_manager_sends_pitchyaw_within_limits_only():
    sent, sent_int = [], []
    m = GimbalManager(lambda name, cmd, *p: sent.append((cmd, p)),
                      lambda name, cmd, frame, p, x, y, z: sent_int.append((cmd, frame, p, x, y, z)),
                      GimbalLimits(pitch_min_deg=-60, pitch_max_deg=0))
    m.point(-45, 30)
    assert sent[0][0] == 1000 and sent[0][1][:2] == (-45.0, 30.0) and all(math.isnan(v) for v in sent[0][1][2:4])
    with pytest.raises(ValueError, match="pitch_deg -70"):
        m.point(-70, 0)
    # the vehicle's own limits, from its GIMBAL_MANAGER_INFORMATION (radians on the wire), narrow ours further
    info = _wire(mav.MAVLink_gimbal_manager_information_message(
        1000, 0, 1, -0.5, 0.5, math.radians(-50), math.radians(20), math.radians(-90), math.radians(90)))
    m.on_message(info, 0.0)
    with pytest.raises(ValueError, match="pitch_deg -55"):
        m.point(-55, 0)
    with pytest.raises(ValueError, match="yaw_deg 120"):
        m.point(-10, 120)
    assert len(sent) == 1
    m.point_at(13.0213, 77.5671, -25.0)
    assert sent_int == [(195, 6, (0.0, 0.0, 0.0, 0.0), 130213000, 775671000, -25.0)]


def test_the_manager_reads_the_device_attitude():
    m = GimbalManager(lambda *a: None, lambda *a: None)
    q = quaternion_from_euler(0.0, -45.0, 30.0)
    status = _wire(mav.MAVLink_gimbal_device_attitude_status_message(
        255, 190, 12345, 4 | 8 | 32, q, 0, 0, 0, 0, math.nan, math.nan, 1))
    att = m.on_message(status, 7.5)
    assert att is not None and att == m.attitude
    assert (att.pitch_deg, att.yaw_deg, att.yaw_in_earth_frame, att.time_boot_ms) == \
        (pytest.approx(-45.0), pytest.approx(30.0), False, 12345)
    unknown = _wire(mav.MAVLink_gimbal_device_attitude_status_message(
        255, 190, 12400, 0, [math.nan] * 4, 0, 0, 0, 0, math.nan, math.nan, 1))
    assert m.on_message(unknown, 8.0) is None and m.attitude == att  # an unknown attitude replaces nothing


def test_the_emulated_gimbal_speaks_what_the_manager_reads():
    from aerodaas.emulators.mavlink.gimbal import EmulatedGimbal

    enc = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    g = EmulatedGimbal(GimbalLimits(rate_deg_s=90.0))
    assert g.command(1000, [-100.0, 0, math.nan, math.nan, 0, 0, 0], lambda *a: a) == mav.MAV_RESULT_DENIED
    assert g.command(1000, [-45.0, 30.0, math.nan, math.nan, 0, 0, 0], lambda *a: a) == mav.MAV_RESULT_ACCEPTED
    for _ in range(20):
        g.step(0.1, (0.0, 0.0, 10.0), 90.0)
    m = GimbalManager(lambda *a: None, lambda *a: None)
    att = m.on_message(_wire_built(g.build(285, enc, 1000), enc), 1.0)
    assert att.pitch_deg == pytest.approx(-45.0) and att.yaw_deg == pytest.approx(30.0)
    m.on_message(_wire_built(g.build(280, enc, 1000), enc), 1.0)
    assert m.vehicle_limits.pitch_min_deg == pytest.approx(-90.0)
    # a region of interest: the emulator aims from the vehicle's pose as the firmware does
    assert g.command(195, [0, 0, 0, 0, 1.0, 2.0, 3.0], lambda lat, lon, alt: (30.0, 40.0, 0.0)) == 0
    for _ in range(40):
        g.step(0.1, (0.0, 0.0, 50.0), 90.0)
    assert (g.model.pitch_deg, g.model.yaw_deg) == pytest.approx(roi_angles((0, 0, 50), 90.0, (30, 40, 0)))


def _wire_built(msg, enc):
    return mav.MAVLink(None).parse_char(bytearray(msg.pack(enc)))
