"""MAVLink signing that cannot be forgotten (aerodaas/backends/mavlink/signing.py, its ``SignedOnly``,
aerodaas/config/environment.py): an unsigned link is said out loud (a ``link_not_signed`` event, a line in the run
summary), and ``mavlink.require_signing`` (per robot, or for every MAVLink robot of the environment) refuses to
move a vehicle over an unsigned link, before Ray when the configuration alone shows it. Judged by the emulated
autopilot's own state, the exit code and message a user meets, and the summary text."""
from __future__ import annotations

import json

import pytest

from aerodaas.backends.base import CredentialsRefused
from tests.inputs.test_app_errors_before_ray import _cli, _refused_before_ray, _write
from tests.mavlink.emulated import position_ready, run_until, with_max_speed
from tests.mavlink.test_mavlink_signing import KEY, _key_file


def _summary(events: list[dict]) -> str:
    from aerodaas.runtime.driver import MissionResult
    from aerodaas.runtime.report import format_summary

    rep = {"t": 1.0, "state": "LANDED", "battery_pct": 90.0, "events": events}
    return format_summary(MissionResult(outcome="success", robots={"quad": rep}, stats={}, latency={},
                                        recording=None, wall_s=1.0))


def test_an_unsigned_link_is_an_event_and_a_line_of_the_run_summary(fly):
    _, b = fly("ardupilot", mavlink={"set_speed_limits": False})
    events = b.drain_events()
    said = [e for e in events if e["event"] == "link_not_signed"]
    assert len(said) == 1 and said[0]["connection"] == b.cfg.connection, said
    text = _summary(events)
    assert f"MAVLink link NOT SIGNED ({b.cfg.connection})" in text, text


def test_a_signed_link_is_not_called_unsigned(fly, tmp_path):
    _, b = fly("ardupilot", signing_key=KEY,
               mavlink={"signing_key_file": _key_file(tmp_path / "v.key"), "set_speed_limits": False})
    events = b.drain_events()
    assert "connected" in {e["event"] for e in events}
    assert "link_not_signed" not in {e["event"] for e in events}
    assert "NOT SIGNED" not in _summary(events)


def test_require_signing_refuses_to_move_a_vehicle_over_an_unsigned_link(fly):
    """The backend made from Python (no environment file, so no pre-flight check): connected unsigned, it refuses
    to arm, take off, fly to a target, set a velocity or start a mission, naming the robot; the vehicle never
    armed and saw no command of ours that moves it. Landing and holding are not refused (stopping never is)."""
    emu, b = fly("ardupilot", mavlink={"require_signing": True, "set_speed_limits": False})
    assert run_until(b, lambda: position_ready(b), 20)
    for call in (b.actions.arm, lambda: b.actions.takeoff(5.0), lambda: b.guidance.goto([0, 5, 5]),
                 lambda: b.guidance.set_velocity([1, 0, 0]), b.mission.start):
        with pytest.raises(CredentialsRefused) as e:
            call()
        assert "robot 'quad'" in str(e.value) and "mavlink.require_signing is true" in str(e.value), e.value
        assert "not signed" in str(e.value)
    run_until(b, lambda: False, 0.5)
    vehicle = emu.snapshot()
    assert not vehicle["armed"] and not vehicle["in_air"]
    moving = {400, 22, 300, 176}  # ARM_DISARM, NAV_TAKEOFF, MISSION_START, DO_SET_MODE
    assert not moving & set(vehicle["commands_seen"]), vehicle["commands_seen"]
    b.guidance.hold()  # not refused: it cannot move a vehicle on the ground anywhere


def test_require_signing_arms_over_a_signed_link(fly, tmp_path):
    """The control: the same requirement with the vehicle's key, over a link that signs, arms."""
    emu, b = fly("ardupilot", signing_key=KEY, mavlink={"require_signing": True, "set_speed_limits": False,
                                                        "signing_key_file": _key_file(tmp_path / "v.key")})
    assert run_until(b, lambda: position_ready(b), 20)
    b.actions.arm()
    assert run_until(b, lambda: emu.snapshot()["armed"], 10)
    b.actions.disarm()


def _env(tmp_path, robot_mavlink: dict, top: dict | None = None) -> None:
    data = {"robots": [{"id": "d1", "backend": "mavlink", "mavlink": robot_mavlink}],
            "compute": [{"id": "edge", "tier": "edge"}], **(top or {})}
    (tmp_path / "env.json").write_text(json.dumps(data))


@pytest.mark.parametrize("where,robot,top,field", [
    ("robot", {"require_signing": True}, None, "robots.0.mavlink.require_signing"),
    ("environment", {}, {"mavlink": {"require_signing": True}}, "mavlink.require_signing"),
])
def test_require_signing_without_a_key_file_is_refused_before_ray(tmp_path, where, robot, top, field):
    app = _write(tmp_path)
    _env(tmp_path, {"connection": "tcp:127.0.0.1:5760", **robot}, top)
    p, ray_tmp = _cli(tmp_path, "run", app)
    _refused_before_ray(p, ray_tmp, field, "robot 'd1' has no mavlink.signing_key_file")


def test_the_environment_wide_requirement_reaches_every_mavlink_robot_and_a_robot_may_set_its_own(tmp_path):
    from aerodaas.backends import make_backend
    from aerodaas.config import parse_environment_config

    key = _key_file(tmp_path / "v.key")
    cfg = parse_environment_config({
        "mavlink": {"require_signing": True},
        "robots": [{"id": "a", "backend": "mavlink", "mavlink": {"signing_key_file": key}},
                   {"id": "b", "backend": "mavlink", "mavlink": {"connection": "tcp:127.0.0.1:5761",
                                                                 "require_signing": False}},
                   {"id": "s", "backend": "sim"}]}, base_dir=str(tmp_path))
    a, b, _ = cfg.robots
    assert a.backend_settings().require_signing is True and b.backend_settings().require_signing is False
    assert make_backend(a).cfg.require_signing is True  # what the backend itself reads
    default = parse_environment_config({"robots": [{"id": "a", "backend": "mavlink"}]})
    assert default.robots[0].backend_settings().require_signing is False


@pytest.mark.e2e
def test_an_unsigned_survey_says_so_in_its_recording_and_summary(ray_session, run_options, tmp_path):
    """Through the whole runtime (Ray, the drone actor, the recorder): apps/farm_survey.py on an emulated ArduCopter
    with no key flies, and the recording (read with the ``mcap`` package) holds the ``link_not_signed`` event, the
    printed summary its line."""
    from aerodaas.runtime.report import format_summary
    from tests.firmware.sitl import read_recording
    from tests.runtime.test_backends_e2e import _mavlink_variant, _run_app

    emu, env_path = _mavlink_variant("farm_survey", "ardupilot", 10.0, tmp_path)
    with_max_speed(env_path, 2.0)  # the whole survey, faster: what is judged does not depend on the flight
    try:
        res = _run_app("farm_survey", env_path, run_options, tmp_path / "farm.mcap")
    finally:
        emu.stop()
    assert res.outcome == "success", res.robots["quadrotor_base"].get("error")
    ev = [m for _, m in read_recording(tmp_path / "farm.mcap")["/quadrotor_base/events"]]
    said = [e for e in ev if e["event"] == "link_not_signed"]
    assert len(said) == 1 and said[0]["connection"].startswith("tcp:127.0.0.1:"), said
    assert f"MAVLink link NOT SIGNED ({said[0]['connection']})" in format_summary(res)
