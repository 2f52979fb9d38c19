"""The speed margin the MAVLink backend derives from the vehicle's own estimator (GNSS speed against estimated
speed, aerodaas/backends/mavlink/speed_margin.py): the rule, and the backend lowering the vehicle's own limit on an
emulated vehicle whose estimator lets it fly faster than it thinks (judged from the emulator's ground truth and its
parameter store)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aerodaas.backends.mavlink.params import px4_speed_limit
from aerodaas.backends.mavlink.speed_margin import MIN_SAMPLES, MIN_STEP_MPS, SPEED_TOLERANCE, EstimatorSpeedMargin
from aerodaas.config import Limits
from tests.mavlink.emulated import run_until


def test_no_margin_before_enough_samples_then_the_p99():
    m = EstimatorSpeedMargin()
    for _ in range(MIN_SAMPLES - 1):
        m.add(1.3, 1.0)
    cap = m.cap(2.0, 1.75, floor=1.0)
    assert cap.margin_mps is None and cap.cap_mps == 1.75 and cap.holdable
    m.add(1.3, 1.0)
    cap = m.cap(2.0, 1.75, floor=1.0)
    assert cap.margin_mps == pytest.approx(0.3) and cap.cap_mps == 1.75  # 2.2 - 0.3 = 1.9: the rule is lower
    m.add(float("nan"), 1.0)
    assert m.samples == MIN_SAMPLES


@settings(max_examples=200, deadline=None)
@given(max_speed=st.floats(0.2, 15.0), overshoot=st.lists(st.floats(-1.0, 2.0), min_size=MIN_SAMPLES, max_size=400))
def test_the_cap_plus_the_measured_overshoot_fits_the_tolerance_or_is_reported(max_speed, overshoot):
    """Whatever the samples: the cap never exceeds the autopilot's rule or falls below the floor, and cap + p99
    overshoot <= max_speed x 1.1 unless the cap is reported as not holdable."""
    m = EstimatorSpeedMargin()
    for d in overshoot:
        m.add(1.0 + d, 1.0)
    default, floor = px4_speed_limit(max_speed), 0.5 * max_speed
    cap = m.cap(max_speed, default, floor)
    assert floor - 1e-9 <= cap.cap_mps <= default + 1e-9
    if cap.holdable:
        assert cap.cap_mps + cap.margin_mps <= max_speed * (1 + SPEED_TOLERANCE) + 1e-3
    else:
        assert cap.cap_mps == floor


@pytest.fixture
def vehicle(fly):
    """vehicle(autopilot, max_speed m/s, estimator error m/s) -> (emulator, backend), taken off to 3 m."""
    def make(autopilot: str, max_speed: float, error_mps: float):
        emu, b = fly(autopilot, limits=Limits(max_speed=max_speed), estimate_speed_error_mps=error_mps)
        b.actions.arm()
        b.actions.takeoff(3.0)
        assert run_until(b, lambda: b.state().position[2] > 2.8, 20)
        return emu, b

    return make


def _legs(emu, b, n: int, events: list) -> list[list[float]]:
    """Fly ``n`` 12 m legs back and forth; the emulator's true horizontal speeds of each leg."""
    out = []
    for k in range(n):
        target = (12.0 if k % 2 == 0 else 0.0, 0.0, 3.0)
        speeds: list[float] = []
        b.guidance.goto(target)
        assert run_until(b, lambda: math.dist(b.state().position, target) < 0.3, 40,
                         every=lambda: speeds.append(float(np.hypot(*emu.state.veh.state.velocity[:2])))), b.state().position
        events.extend(b.drain_events())
        out.append(speeds)
    return out


@pytest.mark.realtime  # PX4 leaves OFFBOARD when our setpoints starve: at load 10-16 beside two xdist workers
@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_an_estimator_that_underreports_speed_gets_the_vehicles_limit_lowered(vehicle, autopilot):
    """The estimator reports 0.8 m/s less than the vehicle flies (GNSS has the truth): the vehicle first flies
    its rule's limit + 0.8 (PX4 1.75 + 0.8, ArduCopter 2.0 + 0.8, beyond 2.2), then the backend lowers the
    vehicle's own limit (and PX4's moving setpoint) to 2.2 - margin, and the true speed stays within max_speed +
    10 % from then on."""
    emu, b = vehicle(autopilot, 2.0, 0.8)
    events: list = []
    speeds = _legs(emu, b, 2, events)
    for _ in range(5):  # enough steady samples at speed: 10 vehicle seconds of it (about 3 legs)
        if any(e["event"] == "speed_margin" for e in events):
            break
        _legs(emu, b, 2, events)  # there and back
    worker = b.speed_limits.worker  # a lowering started in the last leg: its event comes after the vehicle's write
    if worker is not None:
        worker.join(timeout=60)
    events.extend(b.drain_events())
    lowered = [e for e in events if e["event"] == "speed_margin"]
    assert lowered, [e["event"] for e in events]
    # p99 of samples that are 0.8 once steady (more where the GNSS sample is newer than the estimate in a speed
    # change: a larger margin only lowers the limit further). Between two checks of the test the backend may lower
    # the limit more than once (CI of 2026-11-24: 1.335 then 1.249 m/s on a loaded machine): each time by a larger
    # margin, and the vehicle holds the last one
    for e in lowered:
        assert 0.75 <= e["margin_mps"] <= 1.2 and e["samples"] >= MIN_SAMPLES, e
        assert e["cap_mps"] == pytest.approx(2.2 - e["margin_mps"], abs=1e-3), e
    caps = [e["cap_mps"] for e in lowered]
    assert all(a - b >= MIN_STEP_MPS - 1e-3 for a, b in zip(caps, caps[1:])), caps  # only lowered, by a step
    cap = caps[-1]
    param = "MPC_XY_VEL_MAX" if autopilot == "px4" else "WPNAV_SPEED"
    assert emu.params[param] == pytest.approx(cap * (1 if autopilot == "px4" else 100), rel=1e-3)
    if autopilot == "ardupilot":  # before: the rule's limit + the estimator's error (the emulated PX4 follows our
        assert max(speeds[0]) > 2.3  # moving OFFBOARD setpoint's true position, so its error shows only in AUTO)
    n = len(events)
    after = _legs(emu, b, 2, events)
    assert not [e for e in events[n:] if e["event"] == "speed_limit_update_failed"]
    assert max(max(s) for s in after) <= 2.2 + 0.05, [round(max(s), 3) for s in after]
    assert not [e for e in events if e["event"] == "speed_limit_unholdable"]


def test_a_limit_the_estimator_cannot_hold_is_reported_not_flown_as_held(vehicle):
    """max_speed 0.5 with an estimator 0.4 m/s short: no limit above the floor (0.25) fits 0.55 - 0.4, so the
    backend says so once (speed_limit_unholdable, with the figures) and flies at the floor."""
    emu, b = vehicle("ardupilot", 0.5, 0.4)
    events: list = []
    for _ in range(4):  # 12 m legs at 0.9 m/s true: 65 samples at speed in two
        _legs(emu, b, 2, events)
        if any(e["event"] == "speed_margin" for e in events):  # the write done (after the unholdable report)
            break
    bad = [e for e in events if e["event"] == "speed_limit_unholdable"]
    assert len(bad) == 1 and bad[0]["margin_mps"] == pytest.approx(0.4, abs=0.1) and bad[0]["max_speed"] == 0.5
    assert emu.params["WPNAV_SPEED"] == pytest.approx(25.0, abs=1e-3)


def test_an_honest_estimator_leaves_the_limit_alone(vehicle):
    emu, b = vehicle("ardupilot", 2.0, 0.0)
    events: list = []
    _legs(emu, b, 4, events)
    assert b.speed_limits._speed_margin.samples >= MIN_SAMPLES  # it was measured (0 m/s), not skipped
    assert not [e for e in events if e["event"] in ("speed_margin", "speed_limit_unholdable")]
    assert emu.params["WPNAV_SPEED"] == pytest.approx(200.0)


def test_the_summary_says_when_the_limit_was_lowered_or_cannot_hold():
    from aerodaas.runtime.driver import MissionResult
    from aerodaas.runtime.report import format_summary

    events = [{"event": "speed_margin", "margin_mps": 0.62, "samples": 80, "cap_mps": 1.58, "max_speed": 2.0},
              {"event": "speed_limit_unholdable", "margin_mps": 0.54, "samples": 120, "cap_mps": 0.25,
               "max_speed": 0.5}]
    res = MissionResult(outcome="success", robots={"q": {"t": 1.0, "state": "LANDED", "events": events}}, stats={},
                        latency={}, recording=None, wall_s=1.0)
    text = format_summary(res)
    assert "speed limit lowered to 1.58 m/s" in text and "0.62 m/s faster than its estimate" in text
    assert "speed limit NOT holdable" in text and "max_speed 0.5 m/s" in text
    assert "MAVLink link" not in text


def test_the_summary_says_how_many_messages_the_link_lost():
    from aerodaas.runtime.driver import MissionResult
    from aerodaas.runtime.report import format_summary

    events = [{"event": "link_messages_lost", "lost": 5, "total": 5, "received": 95, "lost_pct": 5.0},
              {"event": "link_messages_lost", "lost": 7, "total": 12, "received": 188, "lost_pct": 6.0},
              {"event": "link_messages_dropped", "dropped": 3, "total": 3}]
    res = MissionResult(outcome="success", robots={"q": {"t": 1.0, "state": "LANDED", "events": events}}, stats={},
                        latency={}, recording=None, wall_s=1.0)
    text = format_summary(res)
    assert "at least 12 of 200 messages from the vehicle lost on the way (6.0 %" in text, text
    assert "MAVLink link: 3 messages of the vehicle dropped here" in text, text
