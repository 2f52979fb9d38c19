"""One id grammar (aerodaas.model.ids): robots, sensors, compute resources, targets, analytics and
plug-in names. Ids with a newline, NUL, blanks, '/', a right-to-left override, a zero-width space, non-ASCII
look-alikes or case twins were accepted; robot ``a`` with camera ``camera/X`` and robot ``a/camera`` with camera
``X`` shared one topic (84 frames rendered, 37 recorded, "success")."""
from __future__ import annotations

import json

import pytest
from hypothesis import given, settings, strategies as st

from aerodaas.config import ConfigError, parse_environment_config
from aerodaas.model.ids import RESERVED, ROOT_RESERVED, check_id

from tests.inputs.cli_inprocess import run_cli

GOOD_IDS = ["d1", "quadrotor_base", "Edge-2", "x" * 64, "A"]
BAD_IDS = {
    "": "empty",
    "d1\n": "U+000A",
    "d\x001": "U+0000",
    "d 1": "U+0020 SPACE",
    "d1 ": "U+0020 SPACE",
    "a/camera": "not of the id grammar",
    "d\u202e1": "U+202E RIGHT-TO-LEFT OVERRIDE",
    "d\u200b1": "U+200B ZERO WIDTH SPACE",
    "dr\u00f6hne": "U+00F6",
    "cafe\u0301": "U+0301 COMBINING ACUTE ACCENT",
    "x" * 65: "longer than 64",
    "1drone": "starting with a letter",
    "det#1": "not of the id grammar",
}


@pytest.mark.parametrize("value", GOOD_IDS)
def test_an_id_of_the_grammar_is_accepted(value):
    assert check_id(value) == value


@pytest.mark.parametrize("value,named", BAD_IDS.items())
def test_an_id_outside_the_grammar_is_refused_with_what_a_reader_cannot_see_spelled_out(value, named):
    with pytest.raises(ValueError) as e:
        check_id(value, "robot id")
    assert str(e.value).startswith("robot id ") and named in str(e.value), str(e.value)


def _env(robots: list[dict], compute: list[dict] | None = None) -> dict:
    return {"robots": robots, **({"compute": compute} if compute is not None else {})}


def _robot(rid: str, *sensors: tuple[str, str]) -> dict:
    return {"id": rid, "sensors": [{"id": s, "type": t} for s, t in sensors]}


@pytest.mark.parametrize("env,field,named", [
    (_env([_robot("d1\n")]), "robots.0.id", "U+000A"),
    (_env([_robot("a", ("camera/X", "camera"))]), "robots.0.sensors.0.id", "'camera/X'"),
    (_env([_robot("a/camera", ("X", "camera"))]), "robots.0.id", "'a/camera'"),
    (_env([_robot("d1"), _robot("D1")]), "robots", "['d1', 'D1']: the same id but for case"),
    (_env([_robot("d1", ("cam", "camera"), ("CAM", "camera"))]), "robots.0", "['cam', 'CAM']"),
    (_env([_robot("d1")], [{"id": "edge", "tier": "edge"}, {"id": "Edge", "tier": "cloud"}]), "compute", "['edge', 'Edge']"),
    (_env([_robot("d1")], [{"id": "edge\u200b", "tier": "edge"}]), "compute.0.id", "ZERO WIDTH SPACE"),
    (_env([_robot("mission")]), "robots.0.id", "top-level topic"),
    (_env([_robot("World")]), "robots.0.id", "top-level topic"),
])
def test_an_environment_with_such_an_id_is_refused_naming_the_field(env, field, named):
    with pytest.raises(ConfigError) as e:
        parse_environment_config(env)
    assert field in str(e.value) and named in str(e.value), str(e.value)


def test_a_plugin_sensor_may_not_take_a_name_aerodaas_records_under_the_robot(tmp_path, monkeypatch):
    """A sensor plug-in records on /<robot>/<sensor id>: called ``odometry`` it would share the robot's odometry."""
    (tmp_path / "thermal_probe.py").write_text(
        "from aerodaas.plugins import SensorPlugin\n\n"
        "class ThermalProbe(SensorPlugin):\n"
        "    def sample(self, state, t):\n        return {'t': t}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    env = _env([_robot("d1", ("odometry", "thermal_probe:ThermalProbe"))])
    with pytest.raises(ConfigError) as e:
        parse_environment_config(env)
    assert "robots.0.sensors.0" in str(e.value) and "'odometry' is a name AeroDaaS records under each robot" \
        in str(e.value), str(e.value)


def test_a_plugin_registered_under_a_name_outside_the_grammar_is_refused():
    from aerodaas import MonitoringAnalytics
    from aerodaas.plugins.registry import register

    class Probe(MonitoringAnalytics):
        pass

    for bad in ("probe/x", "probe x", "mod:Probe", "pro\u202ebe", "9probe"):
        with pytest.raises(ValueError, match="analytics plug-in name .* is not of the plug-in name grammar"):
            register(Probe, "analytics", bad)


APP = """from aerodaas import *
env = Environment({env!r})
drone = env.get_robot_by_id("d1")
odom = drone.get_sensor_by_id("odom").get_data_stream()
a = MonitoringAnalytics(name={a!r})
b = MonitoringAnalytics(name={b!r})
a.analyse(odom)
b.analyse(odom)
drone.navigate(AeroListData([Waypoint(id="w1", x=1, y=0, z=2)]))
result = drone.start_mission()
"""


@pytest.mark.parametrize("a,b,named", [
    ("watch", "Watch", "robot 'd1': the analytics' names (name=...): duplicate ids ['watch', 'Watch']"),
    ("watch", "camera", "analytics name (MonitoringAnalytics) 'camera' is a name AeroDaaS records under each robot"),
    ("watch", "w/x", "analytics name (MonitoringAnalytics) 'w/x' is not of the id grammar"),
    ("watch", "Odom", "robot 'd1': analytics name (MonitoringAnalytics) 'Odom' is the id of its sensor 'odom'"),
])
def test_analytics_names_are_ids_and_distinct_per_robot_before_ray(tmp_path, a, b, named):
    """Their names are part of their topics (/<robot>/<name>/...): refused by ``aerodaas plan`` (no Ray), exit 2."""
    env = tmp_path / "env.json"
    env.write_text(json.dumps(_env([_robot("d1", ("odom", "odometry"))])))
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(env), a=a, b=b))
    r = run_cli("plan", str(app))
    assert r.returncode == 2 and named in r.stderr, r.stderr[-2000:]


# ------------------------------------------------------------------ the property: no two components share a topic
#: what a run records under each robot (aerodaas.recording, actors): fixed channels, a camera's, an analytics' and a
#: plug-in sensor's
FIXED = ("events", "odometry", "pose", "gps", "nav/command", "mission/plan", "latency")
ANALYTICS_KINDS = ("detections", "navigation", "tasks", "tracks", "")
BUILTIN_TYPES = ("camera", "odometry")

_text = st.one_of(st.sampled_from(["a", "A", "camera", "Camera", "odometry", "mission", "x/y", "a/camera", "X",
                                   "camera/X", "d1", "D1", "d1 ", "d\u200b1", "nav", "follow"]),
                  st.text(alphabet=st.sampled_from("aAbB1/_- \u200b"), min_size=0, max_size=4))


def _topics(robot: str, sensors: list[tuple[str, str]], analytics: list[str]) -> list[tuple[str, str]]:
    """(topic, owner) of everything a robot records, from the documented layout (docs/recording.md)."""
    out = [(f"/{robot}/{f}", f"{robot}:{f}") for f in FIXED]
    for sid, stype in sensors:
        if stype == "camera":
            out += [(f"/{robot}/camera/{sid}{k}", f"{robot}:cam:{sid}") for k in ("", "/timing", "/video_stats")]
        elif stype == "plugin":
            out.append((f"/{robot}/{sid}", f"{robot}:sensor:{sid}"))
    for name in analytics:
        out += [(f"/{robot}/{name}" + (f"/{k}" if k else ""), f"{robot}:analytics:{name}") for k in ANALYTICS_KINDS]
    return out


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(_text, st.lists(st.tuples(_text, st.sampled_from(["camera", "odometry", "plugin"])),
                                          max_size=3), st.lists(_text, max_size=3)), min_size=1, max_size=3))
def test_no_two_components_of_an_accepted_environment_share_a_topic(robots):
    """For any robots / sensors / analytics names the validators accept, every topic has one owner (and none is a
    top-level topic: /mission/..., /run/..., /world/...)."""
    from aerodaas.model.ids import check_analytics_names, check_topic_name, check_unique

    env = _env([{"id": rid, "sensors": [{"id": sid, "type": t} for sid, t in sensors if t != "plugin"]}
                for rid, sensors, _ in robots])
    try:
        parse_environment_config(env)
        for rid, sensors, analytics in robots:
            for sid, t in sensors:
                if t == "plugin":  # what SensorConfig checks for a plug-in type (no plug-in to import here)
                    check_topic_name(sid, "sensor id")
            check_unique([sid for sid, _ in sensors], "sensors")
            check_analytics_names(rid, [(n, "A") for n in analytics], [sid for sid, _ in sensors])  # as preflight
    except (ConfigError, ValueError):
        return  # refused: nothing to record
    owners: dict[str, str] = {}
    for rid, sensors, analytics in robots:
        assert rid.lower() not in ROOT_RESERVED
        for topic, owner in _topics(rid, sensors, analytics):
            assert owners.setdefault(topic.lower(), owner) == owner, (topic, owners[topic.lower()], owner)
    assert not {"camera", "odometry"} - RESERVED
