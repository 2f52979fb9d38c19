"""Built-ins through the plug-in contract: the built-in sensor types and backends are registered
classes with pydantic ``Config`` models, their settings read from ``backend_config`` (a built-in's section is an
alias), strict and bounded, and listed by ``aerodaas plugins`` like any plug-in."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest
from pydantic import BaseModel

from aerodaas.config import ConfigError, MavlinkConfig, RobotConfig, parse_environment_config
from aerodaas.plugins import SensorPlugin, registry
from aerodaas.backends.base import VehicleBackend


def _robot(**kw) -> dict:
    return {"robots": [{"id": "d1", **kw}]}


@pytest.mark.parametrize("name", ["camera", "odometry", "stat_stream"])
def test_each_builtin_sensor_is_a_sensor_plugin_with_a_config_model(name):
    e = registry.resolve("sensor", name)
    cls = e.load()
    assert e.builtin and issubclass(cls, SensorPlugin) and cls.name == name
    assert issubclass(cls.Config, BaseModel) and cls.Config.model_config.get("extra") == "forbid"


@pytest.mark.parametrize("name", ["sim", "mavlink", "tello", "replay"])
def test_each_builtin_backend_declares_its_settings_model(name):
    cls = registry.get("backend", name)
    assert issubclass(cls, VehicleBackend) and cls.kind == name
    assert issubclass(cls.Config, BaseModel) and cls.Config.model_config.get("strict") is True


def test_aerodaas_plugins_lists_builtins_with_their_settings():
    out = subprocess.run([sys.executable, "-m", "aerodaas.cli", "plugins", "--json"], capture_output=True, text=True,
                         check=True, timeout=120)
    rows = {(r["kind"], r["name"]): r for r in json.loads(out.stdout)}
    assert rows[("sensor", "camera")]["origin"] == registry.BUILTIN_ORIGIN and "width" in rows[("sensor", "camera")]["config"]
    assert rows[("sensor", "odometry")]["config"] == ["rate_hz"]
    assert "connection" in rows[("backend", "mavlink")]["config"] and rows[("backend", "replay")]["config"] == ["log", "rate"]


def test_a_builtin_section_and_backend_config_are_one_place():
    legacy = parse_environment_config(_robot(backend="mavlink", mavlink={"connection": "udpin:0.0.0.0:14551"})).robots[0]
    new = parse_environment_config(_robot(backend="mavlink", backend_config={"connection": "udpin:0.0.0.0:14551"}))
    assert legacy.backend_config == new.robots[0].backend_config and legacy.backend_config["baud"] == 57600
    # the old attribute still reads it, with the environment's require_signing (false) written in
    assert legacy.mavlink == MavlinkConfig(connection="udpin:0.0.0.0:14551", require_signing=False)
    assert RobotConfig(id="q", backend="mavlink", mavlink=MavlinkConfig(baud=9600)).backend_settings().baud == 9600
    assert parse_environment_config(_robot()).robots[0].mavlink is None  # a simulator has no MAVLink settings
    with pytest.raises(ConfigError, match=r"not both"):
        parse_environment_config(_robot(backend="mavlink", mavlink={"baud": 9600}, backend_config={"baud": 9600}))


@pytest.mark.parametrize("robot,match", [
    ({"backend": "mavlink", "mavlink": {"baud": "9600"}}, r"robots\.0\.mavlink\.baud: Input should be a valid integer"),
    ({"backend": "mavlink", "backend_config": {"baud": True}}, r"robots\.0\.backend_config\.baud"),
    ({"backend": "tello", "tello": {"keepalive_s": 20}}, r"robots\.0\.tello\.keepalive_s"),
    ({"backend": "replay", "replay": {"log": "x.tlog", "rate": 0}}, r"robots\.0\.replay\.rate"),
    ({"backend": "replay"}, r"robots\.0\.backend_config\.log: Field required"),
    ({"backend": "sim", "backend_config": {"speed": 1}}, r"robots\.0\.backend_config\.speed: unknown key"),
    ({"backend": "tello", "mavlink": {"baud": 9600}}, r"mavlink: baud: 9600 needs backend 'mavlink'.*'tello'"),
    ({"sensors": [{"id": "c", "type": "camera", "properties": {"width": "640"}}]},
     r"sensors\.0\.properties\.width must be an integer within \[1, 8192\], got '640'"),
    ({"sensors": [{"id": "c", "type": "camera", "properties": {"fps": True}}]},
     r"sensors\.0\.properties\.fps must be a finite number within \(0, 240\], got True"),
    ({"sensors": [{"id": "o", "type": "odometry", "properties": {"rate_hz": 5000}}]},
     r"sensors\.0\.properties\.rate_hz must be a finite number within \(0, 1000\], got 5000"),
    ({"sensors": [{"id": "s", "type": "stat_stream", "properties": {"rate_hz": 1}}]},
     r"sensors\.0\.properties\.rate_hz: unknown stat_stream property"),
])
def test_builtin_settings_are_strict_bounded_and_named_in_errors(robot, match):
    with pytest.raises(ConfigError, match=match):
        parse_environment_config(_robot(**robot))


def test_the_schema_still_describes_the_builtin_sections():
    import jsonschema  # the test extra (pyproject), installed by the README and CI
    from aerodaas.config import json_schema

    schema = json_schema()
    robot = schema["$defs"]["RobotConfig"]["properties"]
    assert {"mavlink", "tello", "replay", "backend_config"} <= set(robot)
    assert robot["mavlink"]["properties"]["fence"]["properties"]["action"]["enum"] == ["rtl", "land", "hold", "report"]
    good = _robot(backend="mavlink", mavlink={"connection": "udpin:0.0.0.0:14550", "fence": {"action": "land"}})
    jsonschema.validate(good, schema)
    good["robots"][0]["mavlink"]["fence"]["action"] = "explode"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(good, schema)


@pytest.mark.parametrize("name,consumes,produces", [
    ("ObjectDetector", ("frame",), ("detections",)), ("FollowAnalytics", ("detections",), ("navigation",)),
    ("MonitoringAnalytics", ("odometry",), ("value",)), ("TrackAnalytics", ("detections",), ("tracks",)),
    ("FallDetector", ("frame",), ("navigation",)), ("StructureLocator", ("frame",), ("detections",)),
    ("InspectionPlanner", ("detections",), ("navigation",)),
])
def test_each_builtin_analytics_declares_what_it_consumes_and_produces(name, consumes, produces):
    """The built-in analytics declare their stream types as a plug-in does (docs/extending.md, "An analytics' output
    contract"): the declaration passes the contract's own check, and ``aerodaas plugins`` lists it."""
    from aerodaas.analytics.contract import check_declaration

    e = registry.resolve("analytics", name)
    cls = e.load()
    assert e.builtin and (cls.consumes, cls.produces) == (consumes, produces)
    check_declaration(cls(**({"template": "any.jpg", "size_m": 3.0} if name == "StructureLocator" else {})))


def test_the_inspection_planner_is_checked_against_its_feed():
    """The paper apps' analytics declare their stream types too (above), so a wrong feed stops the application when
    it is loaded: the planner fed another planner's navigation instead of the locator's detections is refused,
    naming both types; fed the locator it passes."""
    from aerodaas.analytics.contract import ContractError, check_consumes
    from aerodaas.analytics.extra import InspectionPlanner, StructureLocator

    fed = InspectionPlanner()
    fed.analyse(StructureLocator("any.jpg", size_m=3.0).output)
    check_consumes(fed)
    wrong = InspectionPlanner()
    wrong.analyse(InspectionPlanner().output)
    with pytest.raises(ContractError, match=r"consumes \['detections'\], but it is fed the output of analytics "
                                            r"'inspection_planner', which carries \['navigation'\]"):
        check_consumes(wrong)


def test_track_analytics_is_checked_against_its_feed_and_its_output_fields_are_documented():
    """TrackAnalytics takes detections (a stream of another type stops the application before Ray, naming both), and
    every field of its output rows is in docs/extending.md's table of the messages an analytics receives."""
    from pathlib import Path

    from aerodaas.analytics.contract import ContractError, check_consumes
    from aerodaas.analytics.core import MonitoringAnalytics, ObjectDetector
    from aerodaas.analytics.track import TrackAnalytics
    from aerodaas.model.types import CameraIntrinsics, Detection, FrameMeta, FramePose, GeoPoint

    fed = TrackAnalytics()
    fed.analyse(ObjectDetector().output)
    check_consumes(fed)
    wrong = TrackAnalytics()
    wrong.analyse(MonitoringAnalytics().output)
    with pytest.raises(ContractError, match=r"analytics 'tracks' \(TrackAnalytics\) consumes \['detections'\], but it "
                                            r"is fed the output of analytics 'monitor', which carries \['value'\]"):
        check_consumes(wrong)

    meta = FrameMeta(robot_id="d1", sensor_id="cam", seq=0, capture_time=0.0, wall_time=0.0,
                     pose=FramePose(position=(10.0, 5.0, 20.0), yaw=90.0, camera_pitch=90.0),
                     intrinsics=CameraIntrinsics.from_hfov(320, 240, 60.0))
    rows = TrackAnalytics(home=GeoPoint(lat=47.0, lon=8.0, alt=400.0)).process(
        [Detection(class_id=2, class_name="car", score=0.9, box=(150, 110, 170, 130))], meta)
    assert len(rows) == 1 and rows[0]["track_id"] == 1 and rows[0]["enu"] is not None
    docs = (Path(__file__).resolve().parents[2] / "docs" / "extending.md").read_text(encoding="utf-8")
    row = next(line for line in docs.splitlines() if line.startswith("| `TrackAnalytics`, type `tracks` |"))
    assert all(f'"{k}"' in row for k in rows[0]), (sorted(rows[0]), row)
