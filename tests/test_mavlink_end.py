"""The end recorded (issue 26 item 7): a run cut short (its timeout) with the vehicle in the air: the safe end
(LAND commanded, touchdown, disarm) is in the recording as events, the stat-stream goes LANDING -> LANDED, odometry
goes on until the disarm, and the summary says how the run ended. Read with the ``mcap`` package's reader."""
from __future__ import annotations

import pytest

from aerodaas.runtime.report import format_summary

from .sitl import read_recording
from .test_backends_e2e import PX4_AT_SPEED, _mavlink_variant, _run_app


@pytest.mark.e2e
@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_a_run_cut_short_records_the_safe_end_until_disarm(ray_session, run_options, tmp_path, flavour):
    emu, env_path = _mavlink_variant("farm_survey", flavour, 10.0, tmp_path, params=PX4_AT_SPEED[flavour])
    run_options.timeout = 4.0  # wall seconds: 40 s of vehicle time, half the survey
    try:
        res = _run_app("farm_survey", env_path, run_options, tmp_path / "farm.mcap")
        vehicle = emu.snapshot()
    finally:
        emu.stop()
    rep = res.robots["quadrotor_base"]
    assert res.outcome == "timeout", rep.get("error")
    assert not vehicle["armed"]  # the firmware's own state: down and disarmed
    rec = read_recording(tmp_path / "farm.mcap")
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
