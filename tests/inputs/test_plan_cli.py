"""``aerodaas plan``: the run's actors and where they would go, printed without starting Ray or flying."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from tests.conftest import needs_data

ROOT = Path(__file__).resolve().parents[2]


def _plan(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", "plan", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=120, env=dict(os.environ))


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
from aerodaas.bench.overhead import FixedCostDetector
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
    """Issue 27 item 4: two unlabelled edge computes get one selector, so Ray picks the node: said before flying."""
    p = _plan(str(_two_edge_env(tmp_path, [{}, {}])), "--json")
    assert p.returncode == 0, p.stderr[-2000:]
    sels = {json.dumps(a["label_selector"]) for a in json.loads(p.stdout)["actors"] if a["role"] == "drone"}
    assert sels == {'{"tier": "edge"}'}  # the ambiguity the warning is about
    assert "placement between them is Ray's choice" in p.stderr and "'e0', 'e1'" in p.stderr, p.stderr
    assert "aerodaas/compute" in p.stderr
    p = _plan(str(_two_edge_env(tmp_path, [{"aerodaas/compute": "e0"}, {"aerodaas/compute": "e1"}])), "--json")
    assert p.returncode == 0 and "Ray's choice" not in p.stderr, p.stderr
