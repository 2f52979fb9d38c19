"""The analytics output contract (docs/extending.md): a typed ``Output``, named outputs a downstream
analytics subscribes to, ``emit_event``, and ``consumes`` checked against the feeding stream before Ray starts.

The component tests drive the real :class:`AnalyticsComponent` in a plain :class:`DataPlane` (no Ray) with a
recorder that keeps what it is handed; the end-to-end tests run apps with the example plug-in package installed as a
user installs it (tests/plugins/test_example_plugins.py) through ``aerodaas run`` / ``aerodaas plan`` and read the MCAP
recording."""
from __future__ import annotations

import json
import os
import textwrap

import pytest
from pydantic import BaseModel, ValidationError

from aerodaas.analytics.base import Analytics
from aerodaas.analytics.contract import ContractError, check_declaration
from aerodaas.recording.reader import read_messages
from aerodaas.protocol.messages import Port, ValueMsg

from tests.inputs.cli_inprocess import run_cli
from tests.conftest import REPO
from tests.inputs.test_app_value import _ray_processes_under, fresh_ray_tmp
from tests.plugins.test_example_plugins import _aerodaas, _env_with, installed  # noqa: F401 - the fixture: the installed example


class Reading(BaseModel):
    robot: str
    t: float
    level: float


class Spike(BaseModel):
    robot: str
    level: float


class Levels(Analytics):
    """Typed output, one named output, an event above 5."""

    name = "levels"
    Output = Reading
    named_outputs = {"spike": Spike}

    def process(self, data, meta):
        if data["level"] > 5:
            self.emit("spike", Spike(robot=data["robot"], level=data["level"]))
            self.emit_event("level_high", level=data["level"], limit=5)
        if data["level"] < 0:
            return {"something": "else"}  # breaks its declared Output
        if data["level"] == 0:
            return "not a reading"
        return Reading(robot=data["robot"], t=data["t"], level=data["level"])


class _Kept:
    """A recorder that keeps what the component hands it: ``json`` calls as (topic, t_ns, message, schema)."""

    def __init__(self) -> None:
        self.rows: list[tuple[str, int, dict, str]] = []

    def json(self, topic, t_ns, obj, schema_name) -> None:
        self.rows.append((topic, t_ns, obj, schema_name))

    def declare_analytics(self, cid, name) -> None:  # the recorder's accounting of outputs (not under test here)
        pass

    def count_no_output(self, cid, name, robot) -> None:
        pass


def _component(analytics):
    from aerodaas.actors.analytics.component import AnalyticsComponent
    from aerodaas.actors.data.plane import DataPlane

    plane = DataPlane("test", "edge", epoch_ns=0, workers=1)
    rec = _Kept()
    comp = AnalyticsComponent(plane, "levels#1", analytics.name, analytics, rec, epoch_ns=0)
    plane.add(comp)
    return plane, comp, rec


def _item(level: float, t: float = 2.0) -> ValueMsg:
    return ValueMsg(robot="d1", sim_t=t, data={"robot": "d1", "t": t, "level": level})


def test_a_typed_output_is_recorded_with_its_schema_and_published_as_a_dict():
    plane, comp, rec = _component(Levels())
    try:
        out = comp.handle(Port("in"), _item(3.0))
    finally:
        plane.close()
    assert len(out) == 1 and out[0].data == {"robot": "d1", "t": 2.0, "level": 3.0}
    assert rec.rows == [("/d1/levels", 2_000_000_000, {"robot": "d1", "t": 2.0, "level": 3.0}, "tests.Reading")]


def test_a_named_output_and_an_event_are_recorded_with_the_items_robot_and_time():
    plane, comp, rec = _component(Levels())
    try:
        comp.handle(Port("in"), _item(7.5, t=4.0))
    finally:
        plane.close()
    by_topic = {r[0]: r for r in rec.rows}
    assert by_topic["/d1/levels/spike"][2:] == ({"robot": "d1", "level": 7.5}, "tests.Spike")
    assert by_topic["/d1/events"][1:] == (4_000_000_000, {"robot": "d1", "t": 4.0, "event": "level_high",
                                                          "analytics": "levels", "level": 7.5, "limit": 5},
                                          "aerodaas.MissionEvent")
    st = comp.stats()
    assert st["events"] == {"level_high": 1} and st["named_outputs"] == {"spike": 1}


@pytest.mark.parametrize("level, error", [(0.0, "returned a str, but it declares Output = Reading"),
                                          (-1.0, "validation error")])
def test_an_output_that_is_not_the_declared_model_is_a_failed_item(level, error):
    plane, comp, rec = _component(Levels())
    try:
        assert comp.handle(Port("in"), _item(level)) is None
    finally:
        plane.close()
    assert comp.failures == 1 and comp.processed == 0
    (topic, _, ev, schema), = rec.rows
    assert topic == "/d1/events" and ev["event"] == "analytics_error" and error in ev["error"], ev


def test_emit_event_refuses_reserved_fields_bad_kinds_and_values_json_cannot_hold():
    a = Levels()
    with pytest.raises(ValueError, match=r"fields \['robot'\] are set by the runtime"):
        a.emit_event("x", robot="other")
    with pytest.raises(ValueError, match="kind 'two words'"):
        a.emit_event("two words")
    with pytest.raises(ValueError, match="JSON-serialisable"):
        a.emit_event("x", value=float("nan"))
    with pytest.raises(KeyError, match=r"no named output 'spikes'; it declares \['spike'\]"):
        a.output_stream("spikes")
    with pytest.raises(KeyError, match="emit to undeclared output 'peak'"):
        a.emit("peak", {"robot": "d1", "level": 1.0})
    with pytest.raises(ValidationError):
        a.emit("spike", {"robot": "d1"})
    # outside a run (process called directly) what it emits is kept for the caller
    a.process({"robot": "d1", "t": 1.0, "level": 9.0}, None)
    em = a.take_emissions()
    assert [e.kind for _, e in em.events] == ["level_high"] and [o.output for _, o in em.outputs] == ["spike"]
    assert not a.take_emissions().events


def test_a_malformed_declaration_is_refused_naming_the_analytics_and_field():
    class BadOutput(Analytics):
        name = "bad"
        Output = dict

    class BadName(Analytics):
        name = "bad"
        named_outputs = {"detections": Spike}

    for cls, part in ((BadOutput, "Output must be a pydantic BaseModel subclass"),
                      (BadName, "named_outputs key 'detections'")):
        with pytest.raises(ContractError, match=part) as e:
            check_declaration(cls())
        assert "analytics 'bad'" in str(e.value)


MONITOR_ON_CAMERA = textwrap.dedent('''
    from aerodaas import *
    from aerodaas.analytics.core import MonitoringAnalytics
    env = Environment("{env}")
    drone = env.get_robot_by_id("uav")
    MonitoringAnalytics().deploy(env.get_compute_resource_by_id("edge")).analyse(
        drone.get_sensor_by_id("cam").get_data_stream())
    drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=5, y=0, z=8)],
                                  SchedulingType.ORDERED))
    drone.start_mission()
''')


def test_a_builtin_analytics_fed_the_wrong_stream_stops_the_run_before_ray(tmp_path):
    env = tmp_path / "env.json"
    env.write_text(json.dumps({"name": "t", "compute": [{"id": "edge", "tier": "edge"}],
                               "robots": [{"id": "uav", "sensors": [{"id": "cam", "type": "camera"}]}]}))
    app = tmp_path / "app.py"
    app.write_text(MONITOR_ON_CAMERA.format(env=env))
    ray_tmp = fresh_ray_tmp(tmp_path)
    p = run_cli("run", str(app), "--quiet", cwd=tmp_path, env={**os.environ, "RAY_TMPDIR": str(ray_tmp)})
    err = p.stdout + p.stderr
    assert p.returncode == 2, err[-3000:]
    assert ("analytics 'monitor' (MonitoringAnalytics) consumes ['odometry'], but it is fed sensor 'cam' (camera), "
            "which carries ['frame', 'camera']") in err, err[-3000:]
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []  # no Ray session was started


CROSSING_APP = textwrap.dedent('''
    import os
    from pydantic import BaseModel
    from aerodaas import *
    from aerodaas.analytics.core import Analytics
    from aerodaas.plugins import get_plugin
    from aerodaas_example_plugins.plume import PlumeCrossing


    class CrossingNote(BaseModel):
        robot: str
        width_m: float
        duration_s: float


    class CrossingLog(Analytics):
        """Downstream of gas_plume's named output "crossing"."""
        name = "crossing_log"
        consumes = (PlumeCrossing,)
        Output = CrossingNote

        def process(self, data, meta):
            return CrossingNote(robot=data["robot"], width_m=data["width_m"],
                                duration_s=data["left_t"] - data["entered_t"])


    env = Environment("{env}")
    edge = env.get_compute_resource_by_id("edge")
    drone = env.get_robot_by_id("uav")
    plume = get_plugin("analytics", "gas_plume")(enter_ppm=30.0, exit_ppm=15.0).deploy(edge)
    plume.analyse(drone.get_sensor_by_id("gas").get_data_stream())
    log = CrossingLog().deploy(edge)
    log.analyse(plume.output if os.environ.get("WIRE") == "status" else plume.output_stream("crossing"))
    drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="w", x=8, y=0, z=8),
                                  Waypoint(id="e", x=36, y=0, z=8)], SchedulingType.ORDERED))
    drone.start_mission()
''')


def _crossing_app(src, tmp_path):
    def gas_only(c):
        c.pop("analytics_scheduler")
        c["robots"][0]["sensors"] = [s for s in c["robots"][0]["sensors"] if s["id"] == "gas"]

    app = tmp_path / "crossing_app.py"
    app.write_text(CROSSING_APP.format(env=_env_with(src, tmp_path, gas_only)))
    return app


def test_consuming_the_wrong_output_of_an_analytics_is_refused_when_the_app_is_loaded(installed, tmp_path):
    src, env = installed
    app = _crossing_app(src, tmp_path)
    ray_tmp = fresh_ray_tmp(tmp_path)
    p = _aerodaas(["run", str(app), "--quiet"], dict(env, WIRE="status", RAY_TMPDIR=str(ray_tmp)), tmp_path)
    err = p.stdout + p.stderr
    assert p.returncode == 2, err[-3000:]
    assert ("analytics 'crossing_log' (CrossingLog) consumes ['aerodaas_example_plugins.PlumeCrossing'], but it is "
            "fed the output of analytics 'gas_plume', which carries ['aerodaas_example_plugins.PlumeStatus']") in err
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []  # no Ray session was started


@pytest.mark.e2e
def test_a_downstream_analytics_subscribes_to_a_named_output(installed, tmp_path):
    """gas_plume's named output ``crossing`` is a producer of its own in the plan, routed to an analytics in another
    actor; that analytics' typed output derives from the crossing recorded on /uav/gas_plume/crossing."""
    src, env = installed
    app = _crossing_app(src, tmp_path)
    p = _aerodaas(["plan", str(app), "--json"], env, tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]
    plan = json.loads(p.stdout)
    edges = {(e["from"], e["to"]) for e in plan["edges"]}
    assert ("gas_plume#1:crossing", "crossing_log#2") in edges and ("gas_plume#1", "crossing_log#2") not in edges
    actor_of = {n["id"]: n["actor"] for n in plan["nodes"]}
    assert actor_of["gas_plume#1:crossing"] == actor_of["gas_plume#1"] != actor_of["crossing_log#2"]

    rec = tmp_path / "crossing.mcap"
    p = _aerodaas(["run", str(app), "--record", str(rec), "--quiet", "--timeout", "300"], env, tmp_path, timeout=600)
    assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
    msgs: dict[str, list] = {}
    for topic, schema, _, m in read_messages(str(rec)):
        msgs.setdefault(topic, []).append(m)
    crossing, = msgs["/uav/gas_plume/crossing"]
    note, = msgs["/uav/crossing_log"]
    assert note == {"robot": "uav", "width_m": crossing["width_m"],
                    "duration_s": crossing["left_t"] - crossing["entered_t"]}, (note, crossing)
    assert crossing["width_m"] > 15 and crossing["peak_ppm"] > 100, crossing  # it crossed the plume's centre line
    from mcap.reader import make_reader

    with open(rec, "rb") as f:
        summary = make_reader(f).get_summary()
    schema = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}["/uav/crossing_log"]
    # the app's own model: named after the module the app runs as (<its module>.CrossingNote), with its fields
    assert schema.name.endswith(".CrossingNote") and schema.encoding == "jsonschema", schema
    assert {"width_m", "duration_s"} <= set(json.loads(schema.data)["properties"]), schema.data
    assert "analytics crossing_log: 1 items" in p.stdout, p.stdout[-3000:]


@pytest.mark.parametrize("app", sorted(p.name for p in (REPO / "apps").glob("*.py")))
def test_every_shipped_app_passes_the_consumes_check(app, tmp_path):
    """The shipped apps wire built-in analytics that declare ``consumes`` (detector on frames, follow on detections,
    monitor on odometry): the check refuses none of them."""
    p = run_cli("plan", str(REPO / "apps" / app), "--json", cwd=tmp_path)
    assert p.returncode == 0, (p.stdout + p.stderr)[-3000:]
    plan = json.loads(p.stdout[p.stdout.index("\n{") + 1 if not p.stdout.startswith("{") else 0:])  # after notes
    assert any(n["kind"] == "analytics" for n in plan["nodes"])
