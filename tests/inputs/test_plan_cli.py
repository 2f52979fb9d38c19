"""``aerodaas plan``: the run's actors and where they would go, printed without starting Ray or flying."""
from __future__ import annotations

import json
from pathlib import Path

from tests.inputs.cli_inprocess import run_cli
from tests.conftest import needs_data

ROOT = Path(__file__).resolve().parents[2]


def _plan(*args: str):
    """``aerodaas plan ARGS`` in this process (:func:`tests.inputs.cli_inprocess.run_cli`: no Ray, as plan never
    starts it)."""
    return run_cli("plan", *args, cwd=ROOT)


@needs_data
def test_plan_of_vehicle_tracking_lists_the_drone_the_detector_and_the_recorder(data_env):
    p = _plan(str(ROOT / "apps" / "vehicle_tracking.py"), "--json")
    assert p.returncode == 0, p.stderr[-2000:]
    plan = json.loads(p.stdout)
    roles = sorted(a["role"] for a in plan["actors"])
    assert roles == ["analytics", "drone", "recorder"]  # the follow controller is colocated with the drone
    by_role = {a["role"]: a for a in plan["actors"]}
    run = plan["run"]
    assert by_role["drone"]["name"] == f"aerodaas/{run}/drone/quadrotor_base"
    assert by_role["analytics"]["name"] == f"aerodaas/{run}/analytics/edge/detector#1"
    assert by_role["drone"]["label_selector"] == {"tier": "edge"}
    assert any(c.startswith("follow#") for c in by_role["drone"]["components"])
    crossing = [e for e in plan["edges"] if e["from"] == "quadrotor_base/cam1"]
    assert [e["to"] for e in crossing] == ["detector#1"]
    assert "Token authentication" not in p.stderr  # no Ray was started


def test_plan_places_actors_by_compute_labels_and_replicas(tmp_path):
    env = tmp_path / "env.json"
    env.write_text(json.dumps({
        "name": "sites", "drones_per_actor": 2,
        "compute": [{"id": "field-1", "tier": "edge", "labels": {"aerodaas/site": "field-1"}},
                    {"id": "field-2", "tier": "edge", "labels": {"aerodaas/site": "field-2"}},
                    {"id": "dc", "tier": "cloud", "labels": {"aerodaas/gpu": "a10"}}],
        "robots": [{"id": f"d{i}", "compute": "field-1" if i < 2 else "field-2",
                    "sensors": [{"id": "cam", "type": "camera", "properties": {"width": 64, "height": 48}}]}
                   for i in range(4)]}))
    app = tmp_path / "app.py"
    app.write_text(f'''
from aerodaas import *
from aerodaas.bench.pipeline import FixedCostDetector
env = Environment({str(env)!r})
det = FixedCostDetector(5.0)
det.deploy(env.get_compute_resource_by_id("dc"), replicas=2)
for r in env.get_env_robots():
    det.analyse(r.get_sensor_by_id("cam").get_data_stream())
env.start_mission()
''')
    p = _plan(str(app), "--json")
    assert p.returncode == 0, p.stderr[-2000:]
    plan = json.loads(p.stdout)
    sel = {a["name"].split("/", 2)[2]: a["label_selector"] for a in plan["actors"]}
    assert sel["drones/d0+1"] == {"tier": "edge", "aerodaas/site": "field-1"}
    assert sel["drones/d2+1"] == {"tier": "edge", "aerodaas/site": "field-2"}
    reps = sorted(k for k in sel if k.startswith("analytics/"))
    assert len(reps) == 2 and all(sel[k] == {"tier": "cloud", "aerodaas/gpu": "a10"} for k in reps)
    # each drone's frames go to one replica, always the same one
    to = {e["robots"][0] if e["robots"] else e["from"].split("/")[0]: e["to"] for e in plan["edges"]
          if e["from"].endswith("/cam")}
    assert sorted(to) == ["d0", "d1", "d2", "d3"] and len(set(to.values())) == 2


def test_plan_refuses_a_robot_flying_from_an_unknown_compute(tmp_path):
    env = tmp_path / "env.json"
    env.write_text(json.dumps({"robots": [{"id": "d0", "compute": "nowhere"}]}))
    app = tmp_path / "app.py"
    app.write_text(f"from aerodaas import *\nenv = Environment({str(env)!r})\nenv.start_mission()\n")
    p = _plan(str(app))
    assert p.returncode == 2 and "robots.0.compute" in p.stderr and "nowhere" in p.stderr, p.stderr[-1000:]


def _two_edge_env(tmp_path, labels: list[dict]) -> Path:
    env = tmp_path / "env.json"
    env.write_text(json.dumps({
        "name": "two-edges",
        "compute": [{"id": f"e{i}", "tier": "edge", "labels": labels[i]} for i in range(2)],
        "robots": [{"id": f"d{i}", "compute": f"e{i % 2}",
                    "sensors": [{"id": "cam", "type": "camera", "properties": {"width": 64, "height": 48}}]}
                   for i in range(4)]}))
    app = tmp_path / "app.py"
    app.write_text(f"from aerodaas import *\nenv = Environment({str(env)!r})\nenv.start_mission()\n")
    return app


def test_plan_warns_when_two_edge_computes_place_alike_and_not_when_labelled(tmp_path):
    """Two unlabelled edge computes get one selector, so Ray picks the node: said before flying."""
    p = _plan(str(_two_edge_env(tmp_path, [{}, {}])), "--json")
    assert p.returncode == 0, p.stderr[-2000:]
    sels = {json.dumps(a["label_selector"]) for a in json.loads(p.stdout)["actors"] if a["role"] == "drone"}
    assert sels == {'{"tier": "edge"}'}  # the ambiguity the warning is about
    assert "placement between them is Ray's choice" in p.stderr and "'e0', 'e1'" in p.stderr, p.stderr
    assert "aerodaas/compute" in p.stderr
    p = _plan(str(_two_edge_env(tmp_path, [{"aerodaas/compute": "e0"}, {"aerodaas/compute": "e1"}])), "--json")
    assert p.returncode == 0 and "Ray's choice" not in p.stderr, p.stderr


PLAN_APP = '''
from aerodaas import *
from aerodaas.bench.pipeline import FixedCostDetector
from aerodaas.plugins import register_trajectory_scheduler


@register_trajectory_scheduler
class PlanCheckSweep(TrajectoryScheduler):
    """Rows along y, then x (a plug-in registered by decorator in this file)."""
    name = "plan-check-sweep"

    def order(self, waypoints, start):
        return sorted(waypoints, key=lambda w: (w.y, w.x))


env = Environment({env!r})
env.set_trajectory_scheduler(PlanCheckSweep(env))
det = FixedCostDetector(2.0)
det.deploy(env.get_compute_resource_by_id("cloud"))
mon = MonitoringAnalytics(watch=("battery",))
mon.deploy(env.get_compute_resource_by_id("edge"))
det.analyse(env.get_robot_by_id("d0").get_sensor_by_id("cam").get_data_stream())
mon.analyse(env.get_robot_by_id("d0").get_sensor_by_id("odom").get_data_stream())
env.start_mission()
'''


def test_plan_json_is_the_graph_the_runtime_builds_with_edge_types_backends_schedulers_and_every_sensor(tmp_path):
    """``aerodaas plan --json`` names each edge's message types, each robot's backend and trajectory
    scheduler with their origin (a built-in backend, a scheduler registered by decorator in the app) and every
    sensor, also an odometry or stat-stream sensor nobody subscribes to. Compared with the graph the runtime builds
    for the same application (:meth:`Application.plan`, the builder the driver runs, without Ray): the same actors
    and components, the same routes the actors are wired with, and for each robot what its drone actor is
    constructed from (the RobotSpec: backend in its configuration, the scheduler object, its sensor components)."""
    from aerodaas.backends import backend_class
    from aerodaas.runtime.app_loader import load_app

    env = tmp_path / "env.json"
    cam = {"type": "camera", "properties": {"width": 64, "height": 48}}
    env.write_text(json.dumps({
        "name": "plan-check",
        "compute": [{"id": "edge", "tier": "edge"}, {"id": "cloud", "tier": "cloud"}],
        "robots": [{"id": "d0", "sensors": [{"id": "cam", **cam}, {"id": "odom", "type": "odometry"},
                                            {"id": "stat", "type": "stat_stream"}]},
                   {"id": "d1", "sensors": [{"id": "cam", **cam}, {"id": "odom", "type": "odometry"}]}]}))
    app = tmp_path / "plan_check_app.py"
    app.write_text(PLAN_APP.format(env=str(env)))
    p = _plan(str(app), "--json")
    assert p.returncode == 0, p.stderr[-2000:]
    got = json.loads(p.stdout)
    text = _plan(str(app))
    assert text.returncode == 0, text.stderr[-2000:]

    built = load_app(app).plan()  # the runtime's graph of the same application, nothing started
    host = lambda name: name.split("/", 2)[2]  # noqa: E731 - the Ray name without the (random) run id
    assert {host(a["name"]): (a["role"], a["components"]) for a in got["actors"]} == {
        h: (a.role, [str(c) for c in a.components]) for h, a in built.actors.items()}
    routes = {(src, str(dst), port.wire(), buf, robots) for src, rs in built.routes().items()
              for dst, port, buf, robots in rs}
    assert {(e["from"], e["to"], e["port"], e["buffer"], tuple(e["robots"]) if e["robots"] is not None else None)
            for e in got["edges"]} == routes and len(got["edges"]) == len(routes) == 2
    types = {(e["from"], e["to"]): e["types"] for e in got["edges"]}
    assert types[("d0/cam", "detector#1")] == ["frame", "camera"]
    assert types[("d0/odom", "monitor#2")] == ["odometry"]

    specs = {rs.robot_id: rs for a in built.actors.values() for rs in a.spec.robots}
    robots = {r["id"]: r for r in got["robots"]}
    assert sorted(robots) == sorted(specs) == ["d0", "d1"]
    for rid, r in robots.items():
        spec = specs[rid]
        be = backend_class(spec.robot["backend"])
        assert r["backend"] == {"name": spec.robot["backend"], "origin": "entry point aerodaas (built-in)",
                                "class": f"{be.__module__}:{be.__qualname__}"}
        sched = type(spec.scheduler)
        assert r["trajectory_scheduler"]["class"] == f"{sched.__module__}:{sched.__qualname__}"
        assert r["trajectory_scheduler"]["name"] == "PlanCheckSweep"
        assert r["trajectory_scheduler"]["origin"] == f"decorator in {app}", r["trajectory_scheduler"]
        assert [s["id"] for s in r["sensors"]] == [s["id"] for s in spec.robot["sensors"]]
        wired = {c.cid for c in spec.cameras} | set(spec.odom_cids) | set(spec.stat_cids) | {
            ps["cid"] for ps in spec.plugin_sensors}
        assert {s["component"] for s in r["sensors"] if s["component"]} == {str(c) for c in wired}
    assert [(s["id"], s["delivery"], s["component"]) for s in robots["d0"]["sensors"]] == [
        ("cam", "camera", "d0/cam"), ("odom", "vehicle_state", "d0/odom"), ("stat", "mission_status", None)]
    # d1's sensors feed nothing (and the plan records nothing): listed all the same, with no component
    assert [(s["id"], s["component"]) for s in robots["d1"]["sensors"]] == [("cam", None), ("odom", None),
                                                                           ("stat", None)]
    # the text form says the same
    assert "robot d0: backend sim (entry point aerodaas (built-in)), trajectory scheduler PlanCheckSweep (decorator in" in text.stdout
    assert "sensor stat" in text.stdout and "d0/cam -> detector#1 [in] frame | camera" in text.stdout, text.stdout
