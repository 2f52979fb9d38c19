"""The end recorded: a run cut short (its timeout) with the vehicle in the air: the safe end
(LAND commanded, touchdown, disarm) is in the recording as events, the stat-stream goes LANDING -> LANDED, odometry
goes on until the disarm, and the summary says how the run ended. Read with the ``mcap`` package's reader."""
from __future__ import annotations

import pytest

from aerodaas.runtime.report import format_summary
from tests.firmware.sitl import read_recording
from tests.mavlink.emulated import with_max_speed
from tests.runtime.test_backends_e2e import PX4_AT_SPEED, _mavlink_variant, _run_app


def _fly_survey(flavour: str, run_options, tmp_path, land_detect_s: float = 0.0, max_speed: float | None = None):
    """apps/farm_survey.py on an emulated ``flavour`` autopilot at 10x (``max_speed``: the robot's limit in m/s
    instead of the app's); asserts that the emulated autopilot itself ends disarmed. Returns (MissionResult, the
    recording read with the ``mcap`` package)."""
    # PX4 gets 10 vehicle s of COM_OF_LOSS_T (1 wall s at 10x), not PX4_AT_SPEED's 5: a setpoint stream starved for
    # 0.55 wall s (load 40) had PX4's offboard-loss failsafe take the vehicle home, and these tests judge how a run ends
    params = {**PX4_AT_SPEED[flavour], "COM_OF_LOSS_T": 10.0} if flavour == "px4" else PX4_AT_SPEED[flavour]
    emu, env_path = _mavlink_variant("farm_survey", flavour, 10.0, tmp_path, params=params)
    if max_speed is not None:
        with_max_speed(env_path, max_speed)
    emu.state.land_detect_s = land_detect_s
    try:
        res = _run_app("farm_survey", env_path, run_options, tmp_path / "farm.mcap")
        vehicle = emu.snapshot()
    finally:
        emu.stop()
    assert not vehicle["armed"]  # the firmware's own state: down and disarmed
    return res, read_recording(tmp_path / "farm.mcap")


@pytest.mark.e2e
@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_a_run_cut_short_records_the_safe_end_until_disarm(ray_session, run_options, tmp_path, flavour):
    run_options.timeout = 4.0  # wall seconds: 40 s of vehicle time, half the survey
    res, rec = _fly_survey(flavour, run_options, tmp_path)
    rep = res.robots["quadrotor_base"]
    assert res.outcome == "timeout", rep.get("error")
    ev = [m for _, m in rec["/quadrotor_base/events"]]
    names = [e["event"] for e in ev]
    assert "timeout" in names and "safe_end_started" in names, names
    after = ev[names.index("safe_end_started"):]
    after_names = [e["event"] for e in after]
    assert {"mode", "disarmed", "safe_end", "run_end"} <= set(after_names), after_names
    assert any(e["event"] == "mode" and e["name"] == "LAND" for e in after)
    assert next(e for e in after if e["event"] == "safe_end")["result"] == "landed"
    end = next(e for e in after if e["event"] == "run_end")
    assert end["how"] == "safe end: landed and disarmed" and not end["armed"]
    states = [m["state"] for _, m in rec["/mission/state"]]
    assert states[-2:] == ["LANDING", "LANDED"], states[-6:]
    odo = [m for _, m in rec["/quadrotor_base/odometry"]]
    safe_t = next(e for e in ev if e["event"] == "safe_end_started")["t"]
    assert odo[-1]["t"] > safe_t + 1.0 and not odo[-1]["armed"] and not odo[-1]["in_air"]
    assert rep["ended"] == "safe end: landed and disarmed"
    assert "ended: safe end: landed and disarmed" in format_summary(res)



@pytest.mark.e2e
def test_a_completed_mission_is_recorded_until_the_disarm(ray_session, run_options, tmp_path):
    """The survey completes and the vehicle lands. The emulated PX4 denies a disarm until its land detector has
    confirmed the landing (3 s here), as PX4 does ("Disarming denied: not landed"), so the drone's disarm at
    touchdown may be refused at first: the run ends once the vehicle reports itself disarmed, the disarm is in the
    recording after the landing, and the summary says "landed and disarmed". (On PX4 SITL the run used to end at
    touchdown with "state LANDED, armed": tests/firmware/sitl_cases.py _survey_done checks it on the firmware; a vehicle
    that stays armed is disarmed by us, below.)"""
    # 2 m/s, not the app's 0.5: the three 10 m legs were most of the flight, and only its end is judged here
    res, rec = _fly_survey("px4", run_options, tmp_path, land_detect_s=3.0, max_speed=2.0)
    rep = res.robots["quadrotor_base"]
    assert res.outcome == "success", rep.get("error")
    ev = [m for _, m in rec["/quadrotor_base/events"]]
    names = [e["event"] for e in ev]
    after = names[names.index("landed"):]
    assert "disarmed" in after, after
    end = next(e for e in ev if e["event"] == "run_end")
    assert end["how"] == "landed and disarmed" and not end["armed"]
    assert rep["ended"] == "landed and disarmed" and "ended: landed and disarmed" in format_summary(res)


class _Landed:
    """A landed vehicle that stays armed until told (a firmware whose auto-disarm is off, COM_DISARM_LAND -1, after
    a disarm it refused at touchdown)."""

    navigable, in_air = True, False
    telemetry = type("Samples", (), {"sample_key": 0})()

    def __init__(self) -> None:
        self.armed, self.t, self.disarms = True, 100.0, 0
        self.actions = self  # its disarm below

    def state(self):
        from aerodaas.backends.base import VehicleState

        from aerodaas.model.types import GeoPoint

        return VehicleState(t=self.t, position=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0), yaw=0.0, armed=self.armed,
                            in_air=self.in_air, battery_pct=100.0, home=GeoPoint(lat=0.0, lon=0.0, alt=0.0))

    def disarm(self) -> None:
        self.disarms += 1
        self.armed = False

    def drain_events(self) -> list:
        self.t += 1.0  # one vehicle second per look
        return []


class _NoOdometry:
    """The drone's odometry publisher, recording nothing."""

    last = None

    def publish(self, tok=None, *, paced=False):
        pass


def _run_end(backend, events: list):
    """A drone's RunEnd (the drone's own object) on ``backend``, landed, its events appended to ``events``."""
    from aerodaas.actors.drone.end import RunEnd

    from aerodaas.navigation.fsm import MissionState as S

    return RunEnd(backend, "d1", type("F", (), {"state": S.LANDED})(),
                  lambda kind, **kw: events.append({"event": kind, "t": backend.t, **kw}), _NoOdometry())


def test_a_landed_vehicle_that_stays_armed_is_disarmed_by_us_after_its_grace():
    from aerodaas.actors.drone.end import DISARM_WAIT_S

    events: list = []
    e = _run_end(_Landed(), events)
    assert e._await_disarm() == "landed and disarmed (by us)"
    assert e.backend.disarms == 1 and e.backend.t >= 100.0 + DISARM_WAIT_S
    assert [x["event"] for x in events] == ["disarmed_by_us"]


def test_a_vehicle_in_the_air_again_is_never_disarmed_by_the_wait():
    class Airborne(_Landed):
        def drain_events(self) -> list:
            self.in_air = self.t > 103.0  # it took off again (a pilot, the autopilot's own logic)
            return super().drain_events()

    events: list = []
    e = _run_end(Airborne(), events)
    assert e._await_disarm() == "state LANDED, armed"
    assert e.backend.disarms == 0 and events == []
