"""Bad input is refused before anything starts: every case of the reliability catalogue (environment files,
``--record`` paths), the CLI's own flags, empty missions, and — structurally — no Ray process is ever started for
an invalid environment."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from aerodaas import cli
from aerodaas.reliability.catalogue import ENV_CASES, PATH_CASES, check_env_case, check_path_case

pytestmark = pytest.mark.faults


@pytest.mark.parametrize("case", ENV_CASES, ids=[c.name for c in ENV_CASES])
def test_bad_environment_is_refused_naming_the_field(case, tmp_path):
    ok, msg = check_env_case(case, tmp_path)
    assert ok, f"{case.name}: {msg}"


@pytest.mark.parametrize("name,make,expect", PATH_CASES, ids=[c[0] for c in PATH_CASES])
def test_bad_record_path_is_refused_and_nothing_is_created(name, make, expect, tmp_path):
    ok, msg = check_path_case(make, expect, tmp_path)
    assert ok, f"{name}: {msg}"
    assert not (tmp_path / "no").exists()


def test_ulog_without_position_is_refused_before_ray(tmp_path):
    from aerodaas.config import ConfigError, parse_environment_config

    from tests.recording.test_replay import write_ulog

    nopos = tmp_path / "nopos.ulg"
    write_ulog(nopos, {"battery_status": ([("uint64_t", "timestamp"), ("float", "remaining")],
                                          [{"timestamp": 2_000_000, "remaining": 0.5}])}, [])
    env = {"robots": [{"id": "px4", "backend": "replay", "replay": {"log": str(nopos)}}]}
    with pytest.raises(ConfigError, match=r"robots\.0\.replay\.log: .*no vehicle_global_position"):
        parse_environment_config(env)


def test_reliability_file_mission_and_gate_cases(tmp_path):
    """The catalogue's whole-file cases (aerodaas.reliability.file_cases): malformed JSON files named with the
    reason, mission uploads refused before connecting, 100,000-item .plan and WPL files read and checked, the safety
    gate's distance probes; the same rows docs/reliability.md shows."""
    from aerodaas.reliability.file_cases import run_file_cases

    rows = run_file_cases(tmp_path)
    assert len(rows) == 13 and [r for r in rows if not r["refused"]] == [], rows


def test_far_waypoints_are_refused_without_a_geofence():
    from pydantic import ValidationError

    from aerodaas.model.types import VelocityCommand, Waypoint

    with pytest.raises(ValidationError, match="within"):
        Waypoint(id="w", x=1e308, y=0, z=5)
    with pytest.raises(ValidationError, match="within"):
        Waypoint(id="w", x=0, y=0, z=1e6)
    with pytest.raises(ValidationError, match="vx"):
        VelocityCommand(vx=1e308)


APP = """from aerodaas import *
env = Environment({env!r})
drone = env.get_robot_by_id("d1")
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=1, y=0, z=2)]))
drone.start_mission()
"""


@pytest.fixture
def no_ray(monkeypatch):
    """Fails the test if anything tries to start or connect to Ray."""
    from aerodaas.runtime import ray_start

    calls = []
    monkeypatch.setattr(ray_start, "init_ray", lambda address, dashboard=False: calls.append(address))
    monkeypatch.setattr(ray_start, "start_ray_early",
                        lambda address=None, dashboard=False: calls.append(("early", address)))
    # `aerodaas run` shuts Ray down at its end: here that would be the test session's shared Ray (tests after this
    # one found it gone); nothing was started, so there is nothing to stop
    monkeypatch.setattr(ray_start, "shutdown_ray", lambda: None)
    yield calls


@pytest.mark.parametrize("via_flag", [True, False], ids=["--env", "named-by-the-app"])
def test_invalid_environment_never_starts_ray(tmp_path, no_ray, capsys, via_flag):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"robots": [{"id": "d1", "limits": {"max_speed": 1e308}}]}))
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(bad)))
    argv = ["run", str(app), "--quiet"] + (["--env", str(bad)] if via_flag else [])
    assert cli.main(argv) == 2
    assert no_ray == []  # neither the early background start nor a direct start was begun
    assert "robots.0.limits.max_speed" in capsys.readouterr().err


def test_an_application_error_after_a_valid_environment_never_starts_ray(tmp_path, no_ray, monkeypatch):
    """`aerodaas run` builds the whole application without Ray first (as `aerodaas plan` does): a bad waypoint
    after a valid Environment() fails before the early start is even begun."""
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"robots": [{"id": "d1"}]}))
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(good)).replace("x=1, y=0, z=2", "x=1, y=0, z=500"))
    assert cli.main(["run", str(app), "--quiet"]) == 2  # z 500 m above max_altitude 120: SafetyViolation
    assert no_ray == []


def test_a_bad_detector_option_fails_before_ray_subprocess(tmp_path):
    """`Tiling(tile=16)` in an app: exit 2 naming the field,
    and Ray never created a session in a fresh RAY_TMPDIR."""
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"robots": [{"id": "d1"}]}))
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(good)).replace(
        "drone.start_mission()", "from aerodaas.perception.tiling import Tiling\n"
        "d = ObjectDetector('yolox_nano', classes=['car'], tiling=Tiling(tile=16))\n"
        "d.deploy(env.get_compute_resources()[0])\n"
        "drone.start_mission()"))
    p, ray_tmp = _run_in_fresh_ray_tmp(tmp_path, app)
    assert p.returncode == 2, p.stderr
    assert "tiling.tile must be an integer number of pixels within [32, 8192], got 16" in p.stderr
    assert list(ray_tmp.iterdir()) == []


def _run_in_fresh_ray_tmp(tmp_path, app):
    """`aerodaas run APP --quiet` in a subprocess whose RAY_TMPDIR is a new empty folder: (result, that folder)."""
    from tests.inputs.test_app_value import fresh_ray_tmp

    ray_tmp = fresh_ray_tmp(tmp_path)
    env = {**__import__("os").environ, "RAY_TMPDIR": str(ray_tmp)}
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", str(app), "--quiet"], capture_output=True,
                          text=True, env=env, timeout=300), ray_tmp


def test_invalid_environment_subprocess_creates_no_ray_session(tmp_path):
    """The real command, in a fresh RAY_TMPDIR: exit 2, the field named, and Ray never created a session there."""
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"robots": [{"id": "d1", "sensors": [{"id": "c", "type": "camera",
                                                                      "properties": {"widht": 640}}]}]}))
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(bad)))
    p, ray_tmp = _run_in_fresh_ray_tmp(tmp_path, app)
    assert p.returncode == 2, p.stderr
    assert "did you mean 'width'" in p.stderr and "Traceback" not in p.stderr
    assert list(ray_tmp.iterdir()) == []  # no session_* folder: no gcs_server/raylet was ever spawned


@pytest.mark.parametrize("flag,value", [("--speedup", "inf"), ("--speedup", "nan"), ("--speedup", "1e308"),
                                        ("--timeout", "-1"), ("--env", ""), ("--env", "  "), ("--record", ""),
                                        ("--address", "not-a-host:1"), ("--address", "127.0.0.1:1"),
                                        ("--address", "127.0.0.1:70000"), ("--hitl-port", "70000"),
                                        ("--hitl-port", "-1")])
def test_bad_run_flags_exit_2_before_anything(tmp_path, no_ray, capsys, flag, value):
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(tmp_path / "unused.json")))
    assert cli.main(["run", str(app), flag, value]) == 2
    assert no_ray == [] and flag in capsys.readouterr().err


def test_bad_record_path_exits_2_before_ray(tmp_path, no_ray, capsys):
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(tmp_path / "unused.json")))
    assert cli.main(["run", str(app), "--record", str(tmp_path / "missing" / "x.mcap")]) == 2
    assert no_ray == [] and not (tmp_path / "missing").exists()
    assert "does not exist" in capsys.readouterr().err


def _one_waypoint_plan(tmp_path, lat: float, lon: float, alt: float):
    item = {"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, None, lat, lon, alt],
            "autoContinue": True, "doJumpId": 1}
    plan = {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "mission": {"version": 2, "items": [item], "plannedHomePosition": [47.3977, 8.5456, 488.0],
                        "firmwareType": 12, "vehicleType": 2, "cruiseSpeed": 15, "hoverSpeed": 5},
            "geoFence": {"version": 2, "polygons": [], "circles": []}, "rallyPoints": {"version": 2, "points": []}}
    f = tmp_path / "one.plan"
    f.write_text(json.dumps(plan))
    return f


@pytest.mark.parametrize("where, flags, said", [
    ((47.3977, 8.5456, 50_000.0), [], "above max_altitude 120 m"),               # 50 km up
    ((47.3977, 8.5456, 150.0), ["--max-altitude", "100"], "above max_altitude 100 m"),
])
def test_mission_upload_refuses_items_too_high_before_connecting(tmp_path, capsys, where, flags, said):
    """A home-relative altitude needs no home: refused before any connection attempt."""
    f = _one_waypoint_plan(tmp_path, *where)
    assert cli.main(["mission", "upload", str(f), "--connection", "tcp:127.0.0.1:9", "--timeout", "1", *flags]) == 2
    err = capsys.readouterr().err
    assert said in err and "item" in err, err


@pytest.fixture
def vehicle_at_home():
    """An emulated ArduCopter whose home is the test plans' planned home; yields (emulator, connection)."""
    from aerodaas.model.types import GeoPoint
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator

    emu = MavlinkVehicleEmulator("ardupilot", speedup=10.0, gps_lock_s=1.0,
                                 home=GeoPoint(lat=47.3977, lon=8.5456, alt=488.0))
    try:
        yield emu, emu.start("tcp:127.0.0.1:0")
    finally:
        emu.stop()


@pytest.mark.parametrize("where, flags, said", [
    ((1.0, 60.0, 30.0), [], "beyond max_distance 10000 m"),                      # ~6,800 km away
    ((47.4077, 8.5456, 30.0), ["--max-distance", "500"], "1112 m from home, beyond max_distance 500 m"),
])
def test_mission_upload_refuses_items_too_far_from_the_vehicles_home_before_sending(tmp_path, capsys, vehicle_at_home,
                                                                                    where, flags, said):
    """Distances are measured from the vehicle's reported home, and refused before anything is sent."""
    emu, conn = vehicle_at_home
    f = _one_waypoint_plan(tmp_path, *where)
    assert cli.main(["mission", "upload", str(f), "--connection", conn, "--timeout", "10", *flags]) == 2
    err = capsys.readouterr().err
    assert said in err and "item" in err, err
    assert emu.snapshot()["mission_len"] <= 1  # nothing uploaded (ArduPilot keeps its home at 0)


@pytest.mark.parametrize("rally, said", [((47.3977, 8.5456, 500.0), "above max_altitude 120 m"),
                                         ((1.0, 60.0, 30.0), "beyond max_distance 10000 m")])
def test_mission_upload_refuses_rally_points_too_high_or_too_far(tmp_path, capsys, vehicle_at_home, rally, said):
    """The autopilot's RTL may fly to a rally point: the same bounds as the items (the height before connecting, the
    distance from the vehicle's home), before anything is sent."""
    emu, conn = vehicle_at_home
    f = _one_waypoint_plan(tmp_path, 47.3978, 8.5456, 30.0)
    plan = json.loads(f.read_text())
    plan["rallyPoints"]["points"] = [list(rally)]
    f.write_text(json.dumps(plan))
    assert cli.main(["mission", "upload", str(f), "--connection", conn, "--timeout", "10"]) == 2
    err = capsys.readouterr().err
    assert "rally point 1" in err and said in err, err
    assert emu.snapshot()["mission_len"] <= 1


def test_mission_upload_refuses_an_empty_mission(tmp_path, capsys):
    plan = {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "mission": {"version": 2, "items": [], "plannedHomePosition": [47.3977, 8.5456, 488.0],
                        "firmwareType": 12, "vehicleType": 2, "cruiseSpeed": 15, "hoverSpeed": 5},
            "geoFence": {"version": 2, "polygons": [], "circles": []}, "rallyPoints": {"version": 2, "points": []}}
    f = tmp_path / "empty.plan"
    f.write_text(json.dumps(plan))
    # a connection nobody serves: the refusal must come before any connection attempt
    assert cli.main(["mission", "upload", str(f), "--connection", "tcp:127.0.0.1:9", "--timeout", "1"]) == 2
    assert "no items" in capsys.readouterr().err


APP_RAISING = """
from aerodaas import *
cfg = {{"a": 1}}
def plan():
    return cfg[{key!r}]   # the app's own bug
plan()
"""


@pytest.mark.parametrize("key", ["missing"])
def test_an_exception_of_the_app_is_the_apps_exit_1_with_its_traceback(tmp_path, no_ray, capsys, key):
    """A KeyError raised by the application's own code is the app's (exit 1, its traceback), not bad input (2)."""
    app = tmp_path / "my_app.py"
    app.write_text(APP_RAISING.format(key=key))
    assert cli.main(["run", str(app), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert f"the application {str(app)!r} raised KeyError" in err
    assert "Traceback" in err and "my_app.py" in err and "return cfg[" in err
    assert "cli.py" not in err  # the traceback starts at the app


def test_a_runtime_error_of_the_app_exits_1(tmp_path, no_ray, capsys):
    app = tmp_path / "app.py"
    app.write_text("import json\njson.loads('{not json')\n")  # raised inside the standard library, called by the app
    assert cli.main(["run", str(app), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "the application" in err and "JSONDecodeError" in err and "Traceback" in err


def test_bad_input_refused_by_aerodaas_stays_exit_2(tmp_path, no_ray, capsys):
    """The same exception types raised by AeroDaaS about what the app gave it are bad input (exit 2, one line)."""
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(tmp_path / "no_such_env.json")))
    assert cli.main(["run", str(app), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "no_such_env.json" in err and "Traceback" not in err


@pytest.mark.parametrize("hitl", [{"enabled": True, "host": "127.0.0.1", "port": "BUSY"},
                                  {"enabled": True, "host": "192.0.2.1", "port": 0}], ids=["port-in-use", "not-here"])
def test_hitl_address_is_checked_before_ray(tmp_path, no_ray, capsys, hitl):
    """A HITL port that is taken, or a host that is no address of this machine: exit 2 naming it, Ray never
    started (it used to fail after Ray started, with a traceback)."""
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        if hitl["port"] == "BUSY":
            hitl = {**hitl, "port": busy.getsockname()[1]}
        env = tmp_path / "env.json"
        env.write_text(json.dumps({"robots": [{"id": "d1"}], "hitl": hitl}))
        app = tmp_path / "app.py"
        app.write_text(APP.format(env=str(env)))
        assert cli.main(["run", str(app), "--quiet"]) == 2
    assert no_ray == []
    err = capsys.readouterr().err
    assert "hitl" in err and "cannot listen" in err and "Traceback" not in err


def test_reliability_command_line_and_app_error_cases():
    """The catalogue's command-line and application cases (``python -m aerodaas.reliability`` shows them): each
    refused before Ray with exit 2 naming the flag, or reported as the app's own exception (exit 1, traceback)."""
    from aerodaas.reliability.cli_cases import run_cli_cases

    bad = [(r["name"], r["message"][:300]) for r in run_cli_cases() if not r["refused"]]
    assert bad == []


def test_plan_reports_the_apps_own_exception_as_the_apps(tmp_path, capsys):
    app = tmp_path / "my_app.py"
    app.write_text("cfg = {}\ncfg['missing']\n")
    assert cli.main(["plan", str(app)]) == 1
    err = capsys.readouterr().err
    assert "the application" in err and "KeyError" in err and "Traceback" in err


def test_reliability_application_cases(tmp_path):
    """The catalogue's application cases (aerodaas.reliability.app_cases): app values of the wrong type
    or out of bounds, an empty navigation, 50,000 pre-planned waypoints and a NaN waypoint made with model_construct
    (exit 2 before Ray), plug-in modules that do not import (named), --record naming the run's inputs, a WPL numbered
    1, 1, 5, the safety gate's own check, `aerodaas inject` values starting with '-'."""
    from aerodaas.reliability.app_cases import run_app_cases

    rows = run_app_cases(tmp_path)
    names = [r["name"] for r in rows]
    keys = [(r["category"], r["name"]) for r in rows]
    assert len(keys) == len(set(keys)), keys  # each case once
    # the cases this test's docstring names are all there (the catalogue grows)
    for needed in ('Waypoint(x="1") (a string)', "an empty navigation",
                   "50,000 pre-planned waypoints (max_queued_items 5000)", "a NaN waypoint built with model_construct",
                   "backend from a module that does not exist", "--record names the application itself",
                   "QGC WPL numbered 1, 1, 5", "inject --token starting with '-'",
                   "analytics.deploy(\"edge\") (a name, not a compute resource)"):
        assert needed in names, (needed, names)
    assert [(r["name"], r["message"][:300]) for r in rows if not r["refused"] or r.get("traceback")] == []
    assert {r["category"] for r in rows} == {"strict types", "bounds / cross-field", "app-level errors",
                                             "output paths", "plug-in imports", "mission files", "safety gate",
                                             "command line"}


def test_app_values_are_strictly_typed_numbers():
    """Pydantic's lax mode read Waypoint(x='1', y=True) as (1.0, 1.0) and home.lat "13.02" as 13.02."""
    import numpy as np
    from pydantic import ValidationError

    from aerodaas.model.types import GeoPoint, PriorityQueue, VelocityCommand, Waypoint

    for bad in ({"x": "1"}, {"y": True}, {"z": np.bool_(True)}, {"hover_duration": "2"}, {"speed": "1"}):
        with pytest.raises(ValidationError, match="must be a number"):
            Waypoint(id="w", **{"x": 1, "y": 0, "z": 2, **bad})
    w = Waypoint(id="w", x=np.float32(1.5), y=np.int64(2), z=3)  # numpy numbers are numbers
    assert (w.x, w.y, w.z) == (1.5, 2.0, 3.0) and type(w.y) is float
    with pytest.raises(ValidationError, match="must be a number"):
        GeoPoint(lat="13.02", lon=80.0)
    with pytest.raises(ValidationError, match="yaw_rate"):
        VelocityCommand(yaw_rate=1e308)
    with pytest.raises(ValidationError, match="priority"):
        PriorityQueue(None, True)
    with pytest.raises(ValidationError, match="replace"):
        PriorityQueue(None, 1, replace="yes")


def test_the_safety_gate_checks_values_itself():
    """A NaN waypoint built with model_construct passed the pre-flight check and the gate (NaN compares
    False with every limit)."""
    from aerodaas.model.types import ActionCommand, Waypoint
    from aerodaas.config import RobotConfig
    from aerodaas.navigation.safety import SafetyGate, SafetyViolation

    r = RobotConfig.model_validate({"id": "r"})
    gate = SafetyGate(r.safety, r.limits, r.home)
    nan = Waypoint.model_construct(id="n", x=float("nan"), y=0.0, z=2.0, hover_duration=0.0,
                                   waypoint_type="relative", speed=None, acceptance_radius=0.3)
    with pytest.raises(SafetyViolation, match="x must be a finite number") as e:
        gate.check_waypoint(nan)
    assert e.value.field == "x" and gate.rejected == 1
    with pytest.raises(SafetyViolation, match="action"):
        gate.check_item(ActionCommand.model_construct(id="a", action="explode", reason=""))
    ok = Waypoint(id="ok", x=1, y=1, z=2)
    assert gate.check_waypoint(ok) is ok


def test_the_catalogue_guard_reports_tracebacks_and_hangs():
    """A case that lets an exception out is a traceback row, one that never answers a hang row (the report goes
    on either way); both fail `python -m aerodaas.reliability`."""
    import threading

    from aerodaas.reliability.input_report import guarded, summarize

    def raises() -> list:
        raise RuntimeError("cv2.error stand-in")

    rows = guarded(raises, "environment", "raw exception", "files and images", 30.0)
    rows += guarded(lambda: [threading.Event().wait(120.0)], "environment", "never answers", "files and images", 0.5)
    rows += guarded(lambda: [{"kind": "JSON file", "name": "fine", "refused": True, "message": "refused"}],
                    "file", "batch", "x", 30.0)
    s = summarize(rows)
    assert s["tracebacks"] == ["raw exception"] and s["hangs"] == ["never answers"]
    assert s["accepted_wrongly"] == ["raw exception", "never answers"] and rows[2]["category"] == "files and images"


def test_the_summary_never_shows_more_waypoints_reached_than_planned_as_a_fraction():
    """746 waypoints added through the HITL API to a 1-waypoint survey printed "waypoints 747/1"."""
    from aerodaas.runtime.driver import MissionResult
    from aerodaas.runtime.report import format_summary, waypoint_count

    assert waypoint_count(3, 4) == "3/4" and waypoint_count(0, None) == "0/?"
    rep = {"robot": "d1", "outcome": "success", "t": 100.0, "visited": 747, "preplanned_total": 1,
           "state": "LANDED", "battery_pct": 50.0}
    text = format_summary(MissionResult(outcome="success", robots={"d1": rep}, stats={}, latency={}, recording=None,
                                        wall_s=1.0))
    assert "waypoints 747 reached (1 pre-planned, at least 746 added in flight)" in text and "747/1" not in text
