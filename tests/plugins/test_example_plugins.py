"""The plug-in example (examples/plugins, docs/extending.md) installed the way a user installs a package — pip, into
a private target folder put on PYTHONPATH, so nothing global changes and Ray's workers (children of this
environment) import it too — then found through its entry points, run with ``aerodaas run`` on local Ray and on a
two-node LocalCluster, and checked from the recording: each plug-in did its job."""
from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from aerodaas.recording.reader import read_messages

from tests.conftest import REPO, skip_or_fail
from tests.liveview.test_liveview_npm_client import node_client  # noqa: F401 - the fixture: Foxglove's npm client

EXAMPLE = REPO / "examples" / "plugins"
PLUGINS = {("sensor", "gas_concentration"), ("backend", "gusty_sim"), ("backend", "ground_rover"),
           ("analytics", "gas_threshold"),
           ("analytics", "frame_probe"), ("analytics", "gas_plume"), ("analytics_scheduler", "THIN_EDGE_FIFO"),
           ("trajectory_scheduler", "eastward_sweep")}


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(copy of the example, environment with the installed package on PYTHONPATH)."""
    root = tmp_path_factory.mktemp("plugins")
    src = root / "src"
    shutil.copytree(EXAMPLE, src, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    site = root / "site"
    p = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--no-index",
                        "--target", str(site), str(src)], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-3000:]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site)] + [x for x in [env.get("PYTHONPATH")] if x])
    env["AERODAAS_NO_ATTACH"] = "1"  # a Ray of this test's own (its workers see PYTHONPATH), never `aerodaas up`'s
    return src, env


def _aerodaas(args: list[str], env: dict, cwd, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", *args], capture_output=True, text=True, env=env,
                          cwd=cwd, timeout=timeout)


def test_the_installed_package_registers_every_plugin_by_entry_point(installed, tmp_path):
    src, env = installed
    p = _aerodaas(["plugins", "--json"], env, tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]
    rows = {(r["kind"], r["name"]): r for r in json.loads(p.stdout)}
    for key in PLUGINS:
        assert rows[key]["origin"] == "entry point aerodaas-example-plugins", rows.get(key)
        assert "error" not in rows[key], rows[key]
    assert "source_x" in rows[("sensor", "gas_concentration")]["config"]
    assert {"max_speed_mps", "turn_rate_dps"} <= set(rows[("backend", "ground_rover")]["config"])
    assert rows[("backend", "sim")]["origin"] == "entry point aerodaas (built-in)"  # one origin column: the distribution
    assert rows[("analytics_scheduler", "DEMS")]["origin"] == "entry point aerodaas (built-in)"
    # the framework never names the example's sensor type: a new sensor type is one file of the package
    g = subprocess.run(["git", "grep", "-n", "gas_concentration", "--", "aerodaas", "actors", "schedulers"], cwd=REPO,
                       capture_output=True, text=True)
    assert g.returncode == 1 and not g.stdout, g.stdout


SWEEP = textwrap.dedent('''
    from aerodaas import NearestNeighborScheduler, Waypoint
    from aerodaas.plugins import get_plugin
    pts = [Waypoint(id="b", x=3, y=0, z=5), Waypoint(id="a", x=2, y=9, z=5), Waypoint(id="c", x=-4, y=1, z=5)]
    sweep = get_plugin("trajectory_scheduler", "eastward_sweep")()
    print("ORDER", [w.id for w in sweep.order(pts, (0, 0, 5))], [w.id for w in NearestNeighborScheduler().order(pts, (0, 0, 5))])
''')


def test_the_trajectory_scheduler_plugin_orders_west_to_east(installed, tmp_path):
    """The example's trajectory scheduler, taken from the registry as the app takes it, flies an UNORDERED list
    west to east where the built-in nearest-neighbour order differs (the e2e tests check the flown order)."""
    _, env = installed
    p = subprocess.run([sys.executable, "-c", SWEEP], capture_output=True, text=True, env=env, cwd=tmp_path,
                       timeout=120)
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("ORDER ")), None)
    assert line == "ORDER ['c', 'a', 'b'] ['b', 'c', 'a']", p.stdout + p.stderr[-2000:]


def _env_with(src, tmp_path, mutate) -> str:
    cfg = json.loads((src / "app" / "gas_survey.json").read_text())
    mutate(cfg)
    path = tmp_path / "env.json"
    path.write_text(json.dumps(cfg))
    return str(path)


def test_a_misspelt_sensor_type_stops_before_ray_naming_robot_sensor_and_what_is_available(installed, tmp_path):
    src, env = installed
    from tests.inputs.test_app_value import _ray_processes_under, fresh_ray_tmp

    bad = _env_with(src, tmp_path, lambda c: c["robots"][0]["sensors"][1].update(type="gas_concentraton"))
    ray_tmp = fresh_ray_tmp(tmp_path)
    p = _aerodaas(["run", str(src / "app" / "gas_survey.py"), "--env", bad, "--quiet"],
                  dict(env, RAY_TMPDIR=str(ray_tmp)), tmp_path)
    err = p.stdout + p.stderr
    assert p.returncode == 2, err[-3000:]
    for part in ("sensors.1.type", "'uav'", "'gas'", "'gas_concentraton'",
                 "'gas_concentration' (entry point aerodaas-example-plugins)", "'camera' (entry point aerodaas (built-in))"):
        assert part in err, (part, err[-3000:])
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []  # no Ray session was started
    bad_backend = _env_with(src, tmp_path, lambda c: c["robots"][0].update(backend="gusty"))
    p = _aerodaas(["plan", str(src / "app" / "gas_survey.py"), "--env", bad_backend], env, tmp_path)
    err = p.stdout + p.stderr
    assert p.returncode == 2 and "robots.0.backend" in err and "'gusty_sim' (entry point" in err, err[-3000:]
    bad_prop = _env_with(src, tmp_path, lambda c: c["robots"][0]["sensors"][1]["properties"].update(spread_m=-1))
    p = _aerodaas(["plan", str(src / "app" / "gas_survey.py"), "--env", bad_prop], env, tmp_path)
    err = p.stdout + p.stderr
    assert p.returncode == 2 and "sensors.1.properties.spread_m" in err and "-1" in err, err[-3000:]


def test_an_import_path_names_a_plugin_class_in_environment_json(installed, tmp_path):
    src, env = installed
    path_env = _env_with(src, tmp_path, lambda c: (
        c["robots"][0]["sensors"][1].update(type="aerodaas_example_plugins.gas:GasConcentrationSensor"),
        c["robots"][0].update(backend="aerodaas_example_plugins.wind:GustySimBackend")))
    p = _aerodaas(["plan", str(src / "app" / "gas_survey.py"), "--env", path_env, "--json"], env, tmp_path)
    assert p.returncode == 0, (p.stdout + p.stderr)[-3000:]
    plan = json.loads(p.stdout)
    gas = next(n for n in plan["nodes"] if n["id"] == "uav/gas")
    assert gas["kind"] == "sensor" and gas["plugin"].endswith("aerodaas_example_plugins.GasReading"), gas



ROVER_SETTINGS = textwrap.dedent('''
    import copy, json, sys
    from aerodaas.config import ConfigError, parse_environment_config
    base = json.load(open(sys.argv[1]))
    for change in ({"backend_config": {"max_speed_mps": -1}}, {"safety": {"min_altitude": 0.5}}):
        cfg = copy.deepcopy(base)
        for section, values in change.items():
            cfg["robots"][0][section].update(values)
        try:
            parse_environment_config(cfg)
            print("ACCEPTED", change)
        except ConfigError as e:
            print("REFUSED", str(e).replace(chr(10), " "))
''')

ROVER_UP = textwrap.dedent('''
    from aerodaas import *
    env = Environment("rover_patrol.json")
    rover = env.get_robot_by_id("rover")
    rover.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="hill", x=5, y=0, z=2.0)],
                                  SchedulingType.ORDERED))
    rover.start_mission()
''')


def test_the_rover_backend_refuses_bad_settings_and_an_airborne_waypoint_before_ray(installed, tmp_path):
    """The from-scratch backend's own checks, as the framework runs them for a plug-in when it loads the
    environment and the app: its Config (the field and value named), its check_config (the safety floor) and its
    check_mission (a waypoint off the ground; ``aerodaas plan`` exits 2)."""
    src, env = installed
    p = subprocess.run([sys.executable, "-c", ROVER_SETTINGS, str(src / "app" / "rover_patrol.json")],
                       capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith(("REFUSED", "ACCEPTED"))]
    assert len(lines) == 2, p.stdout + p.stderr[-3000:]
    assert lines[0].startswith("REFUSED") and "robots.0.backend_config.max_speed_mps" in lines[0] and "-1" in lines[0]
    assert lines[1].startswith("REFUSED robots.0.safety.min_altitude: 0.5 m; a rover"), lines[1]
    up = tmp_path / "rover_up.py"
    up.write_text(ROVER_UP)
    (tmp_path / "rover_patrol.json").write_text((src / "app" / "rover_patrol.json").read_text())
    p = _aerodaas(["plan", str(up)], env, tmp_path)
    err = p.stdout + p.stderr
    assert p.returncode == 2 and "robot 'rover': waypoint 'hill' at z = 2 m; a rover" in err, err[-3000:]


def _check_rover(rec: str) -> None:
    """The rover app's recording: it drove to each patrol point (an odometry sample within its 0.3 m acceptance
    radius, reached and held in order), always on the ground (never an in-air sample, z = 0), and never took off (no
    TAKING_OFF state, the drone's takeoff_skipped event); its mission a success."""
    msgs: dict[str, list] = {}
    for topic, _, _, m in read_messages(rec):
        msgs.setdefault(topic, []).append(m)
    result = msgs["/mission/result"][-1]
    assert result["outcome"] == "success" and result["visited"] == 3, result
    events = msgs["/rover/events"]
    assert [e["waypoint"] for e in events if e["event"] == "waypoint_done"] == ["p1", "p2", "p3"], events
    assert "takeoff_skipped" in [e["event"] for e in events] and "takeoff" not in [e["event"] for e in events]
    odo = msgs["/rover/odometry"]
    assert len(odo) > 50 and not [o for o in odo if o["in_air"] or o["position"][2] != 0.0]
    for point in ((10.0, 0.0, 0.0), (10.0, 8.0, 0.0), (0.0, 8.0, 0.0)):
        assert min(math.dist(o["position"], point) for o in odo) <= 0.3, point
    states = [m["state"] for m in msgs["/mission/state"]]
    assert "TAKING_OFF" not in states and states[:3] == ["PREFLIGHT", "ARMED", "HOVERING"], states
    end = next(e for e in events if e["event"] == "run_end")
    assert states[-1] == "LANDED" and end["how"] == "landed and disarmed" and not end["armed"], (states[-3:], end)

def _plume(props: dict, pos: list[float]) -> float:
    d2 = (pos[0] - props["source_x"]) ** 2 + (pos[1] - props["source_y"]) ** 2
    return props["background_ppm"] + props["peak_ppm"] * math.exp(-d2 / (2 * props["spread_m"] ** 2))


def _check_recording(rec: str, src) -> None:
    from mcap.reader import make_reader

    cfg = json.loads((src / "app" / "gas_survey.json").read_text())
    props = {"background_ppm": 0.4, **cfg["robots"][0]["sensors"][1]["properties"]}
    msgs: dict[str, list] = {}
    for topic, _, _, m in read_messages(rec):
        msgs.setdefault(topic, []).append(m)
    result = msgs["/mission/result"][-1]
    assert result["outcome"] == "success", result

    # the sensor: its channel, recorded with the JSON Schema of its pydantic message model, readings that follow
    # the plume at the position where they were taken (noise 0.5 ppm)
    with open(rec, "rb") as f:
        summary = make_reader(f).get_summary()
    ch = next(c for c in summary.channels.values() if c.topic == "/uav/gas")
    schema = summary.schemas[ch.schema_id]
    assert schema.name == "aerodaas_example_plugins.GasReading" and schema.encoding == "jsonschema"
    assert {"ppm", "position", "t"} <= set(json.loads(schema.data)["properties"])
    gas = msgs["/uav/gas"]
    assert len(gas) >= 20, len(gas)
    assert max(g["ppm"] for g in gas) > 100 and min(g["ppm"] for g in gas) < 2
    assert all(abs(g["ppm"] - _plume(props, g["position"])) < 3.0 for g in gas), \
        max(abs(g["ppm"] - _plume(props, g["position"])) for g in gas)

    # the backend: it flew the survey (odometry out to x = 36 m) and its gusts happened in flight
    events = msgs["/uav/events"]
    gusts = [e for e in events if e["event"] == "wind_gust"]
    assert len(gusts) >= 5 and all(e["speed_mps"] == 1.0 for e in gusts), len(gusts)
    assert max(o["position"][0] for o in msgs["/uav/odometry"]) > 35.0
    reached = [e["waypoint"] for e in events if e["event"] == "waypoint_reached"]
    # the trajectory scheduler: the survey, listed as wp3, wp1, wp4, wp2, was planned and flown west to east, where
    # the built-in nearest-neighbour order from home differs (so this check tells the plug-in from the default)
    from aerodaas import NearestNeighborScheduler, Waypoint

    plans = msgs["/uav/mission/plan"]
    survey = next(m for p in plans for m in p["missions"] if m["priority"] == 2)
    assert [i["id"] for i in survey["items"]] == ["wp1", "wp2", "wp3", "wp4"], survey
    pts = [Waypoint(id=i["id"], x=i["local"][0], y=i["local"][1], z=i["local"][2]) for i in survey["items"]]
    assert [w.id for w in NearestNeighborScheduler().order(pts, (0.0, 0.0, 8.0))] != ["wp1", "wp2", "wp3", "wp4"]

    # the analytics: one hover command where the gas first crossed 60 ppm, flown before the survey went on
    navs = msgs["/uav/gas_threshold/navigation"]
    assert len(navs) == 1, navs
    wp = navs[0]["waypoints"][0]
    assert wp["id"] == "gas-hover-1" and wp["hover_duration"] == 2.0
    first_high = next(g for g in gas if g["ppm"] >= 60.0)
    assert math.dist(first_high["position"], (wp["x"], wp["y"], wp["z"])) < 0.5, (first_high, wp)
    assert reached == ["wp1", "wp2", "gas-hover-1", "wp3", "wp4"], reached  # the plume is met on the way to wp3

    _check_plume(rec, msgs, summary)

    # the analytics scheduler: every third frame_probe task shed with its reason, the others run on the edge
    tasks = msgs["/uav/frame_probe/tasks"]
    shed = [t for t in tasks if t["reason"] == "thin-edge-fifo: shed"]
    assert len(tasks) >= 30 and abs(len(shed) - len(tasks) / 3) <= 1, (len(shed), len(tasks))
    assert all(t["state"] == "dropped_cost" for t in shed)
    assert sum(t["state"] == "done_on_time" and t["tier"] == "edge" for t in tasks) >= len(tasks) // 2
    assert len(msgs["/uav/frame_probe"]) >= len(tasks) // 2


def _check_plume(rec: str, msgs: dict[str, list], summary) -> None:
    """The non-navigable analytics with an output contract (gas_plume): its typed status per reading, its named
    output ``crossing`` (each on a channel with its pydantic model's JSON Schema) and its two events."""
    schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    for topic, name, fields in (("/uav/gas_plume", "aerodaas_example_plugins.PlumeStatus",
                                 {"ppm", "inside", "peak_ppm"}),
                                ("/uav/gas_plume/crossing", "aerodaas_example_plugins.PlumeCrossing",
                                 {"entered_t", "left_t", "peak_ppm", "peak_position", "width_m"})):
        assert schemas[topic].name == name and schemas[topic].encoding == "jsonschema", (topic, schemas[topic])
        assert fields <= set(json.loads(schemas[topic].data)["properties"]), (topic, schemas[topic].data)
    by_t = {g["t"]: g for g in msgs["/uav/gas"]}
    statuses = msgs["/uav/gas_plume"]
    assert len(statuses) >= len(by_t) // 2, (len(statuses), len(by_t))  # a busy analytics may skip readings
    assert all(by_t[s["t"]]["ppm"] == s["ppm"] for s in statuses)  # each status is of the reading it names
    mine = [e for e in msgs["/uav/events"] if e.get("analytics") == "gas_plume"]
    assert [e["event"] for e in mine] == ["plume_entered", "plume_left"], mine  # the survey crosses it once
    entered, left = mine
    assert entered["ppm"] >= 30.0 > 15.0 > left["ppm"], mine
    assert entered["t"] == next(s["t"] for s in statuses if s["inside"])  # the first status inside
    crossing = msgs["/uav/gas_plume/crossing"]
    assert len(crossing) == 1, crossing
    c = crossing[0]
    assert (c["entered_t"], c["left_t"]) == (entered["t"], left["t"]) and c["peak_ppm"] == left["peak_ppm"], (c, mine)
    assert c["peak_ppm"] == max(s["ppm"] for s in statuses if entered["t"] <= s["t"] < left["t"]) > 100, c
    assert math.isclose(c["width_m"], math.dist(entered["position"][:2], left["position"][:2])), c


@pytest.fixture(scope="module")
def gas_run(installed, request, tmp_path_factory):
    """One ``aerodaas run gas_survey.py --record --live 127.0.0.1:0`` of the example app on local Ray, Foxglove's
    npm client (:func:`node_client`) connected for the whole run when node is there: (exit code, console lines,
    recording, what the client got or None, why there is no client or None). The two tests of the app read it: the
    plug-ins' work from the recording and the summary, the live view channel for channel."""
    from tests.liveview.test_live_and_foxglove import AERODAAS, _start, _wait_for_url
    from tests.liveview.test_liveview_npm_client import _finish

    src, env = installed
    try:
        node_client = request.getfixturevalue("node_client")
        no_client = None
    except pytest.skip.Exception as e:  # no node here: the run still proves the plug-ins, the live test skips
        node_client, no_client = None, str(e)
    rec = tmp_path_factory.mktemp("gas") / "gas.mcap"
    p, lines = _start([*AERODAAS, "run", str(src / "app" / "gas_survey.py"), "--record", str(rec), "--live",
                       "127.0.0.1:0", "--quiet", "--timeout", "300"], env=env)
    got = None
    try:
        url, seen = _wait_for_url(p, lines, "live view at")
        if node_client is not None:
            got = _finish(node_client(url, 300, keep=("/uav/events",)), 320)
        rc = p.wait(timeout=400)
    finally:
        if p.poll() is None:
            p.kill()
    while (line := lines.get(timeout=60)) != "":  # the rest of the console, to its end
        seen.append(line)
    return rc, seen, rec, got, no_client


@pytest.mark.e2e
def test_the_example_app_runs_on_local_ray_and_each_plugin_does_its_job(installed, gas_run):
    src, _ = installed
    rc, console, rec, _, _ = gas_run
    out = "".join(console)
    assert rc == 0, out[-4000:]
    _check_recording(str(rec), src)
    # the run's summary counts the analytics' named outputs and its events by kind
    line = next((ln for ln in console if "analytics gas_plume:" in ln), "")
    assert "outputs crossing 1" in line and "events plume_entered x1, plume_left x1" in line, out[-3000:]


@pytest.mark.e2e
def test_the_rover_app_drives_its_patrol_on_local_ray(installed, tmp_path):
    """The from-scratch ground-rover backend, installed by entry point, run by ``aerodaas run``: exit 0 and a
    recording of a patrol driven on the ground."""
    src, env = installed
    rec = tmp_path / "rover.mcap"
    p = _aerodaas(["run", str(src / "app" / "rover_patrol.py"), "--record", str(rec), "--quiet", "--timeout", "120"],
                  env, tmp_path, timeout=300)
    assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
    _check_rover(str(rec))

CLUSTER = textwrap.dedent('''
    import json, os, subprocess, sys, time
    from aerodaas.clusters.local import LocalCluster

    runs, site = json.loads(sys.argv[1]), sys.argv[2]
    # the cluster's nodes do not have the package (no PYTHONPATH to it): only the driver does, as on a cluster
    # started elsewhere; the driver ships the installed plug-in packages to the job (runtime_env py_modules). The
    # apps run one after the other on the same cluster, each a job of its own.
    with LocalCluster(cloud_nodes=0, edge_nodes=2, edge_labels=[{"aerodaas/site": "a"}, {"aerodaas/site": "b"}],
                      connect=False, worker_niceness=0) as lc:
        for app, env_file, rec in runs:
            args = ["--env", env_file] if env_file else []
            t0 = time.monotonic()
            p = subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", app, *args, "--record", rec, "--quiet",
                                "--timeout", "300", "--address", lc.address], capture_output=True, text=True,
                               timeout=900, env=dict(os.environ, PYTHONPATH=site))
            print("RESULT " + json.dumps({"app": app, "rc": p.returncode, "wall_s": round(time.monotonic() - t0, 1),
                                          "out": p.stdout[-3000:], "err": p.stderr[-3000:]}), flush=True)
''')


@pytest.mark.cluster
def test_the_example_app_runs_on_a_two_node_local_cluster(installed, tmp_path):
    """The drone actor (gusty backend, gas sensor, frame probe's dispatcher and its scheduler) flies from site a,
    the gas-threshold analytics runs on site b. The cluster's nodes were started without the package; the
    driver, where it is installed, ships it to them. Then, on the same cluster, the rover app (its from-scratch
    backend shipped the same way)."""
    src, env = installed

    def two_sites(c):
        c["compute"] = [{"id": "base", "tier": "edge", "labels": {"aerodaas/site": "a"}},
                        {"id": "edge", "tier": "edge", "labels": {"aerodaas/site": "b"}}]
        c["robots"][0]["compute"] = "base"

    env_file = _env_with(src, tmp_path, two_sites)
    p = _aerodaas(["plan", str(src / "app" / "gas_survey.py"), "--env", env_file, "--json"], env, tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]
    sel = {a["role"] + ":" + ",".join(a["components"]): a["label_selector"].get("aerodaas/site")
           for a in json.loads(p.stdout)["actors"]}
    assert sel["analytics:gas_threshold#2"] == "b" and sel["dispatcher:frame_probe#1"] == "a", sel
    rec, rover_rec = tmp_path / "cluster.mcap", tmp_path / "rover.mcap"
    runs = [[str(src / "app" / "gas_survey.py"), env_file, str(rec)],
            [str(src / "app" / "rover_patrol.py"), None, str(rover_rec)]]
    script = tmp_path / "cluster_run.py"
    script.write_text(CLUSTER)
    site = env["PYTHONPATH"].split(os.pathsep)[0]
    cluster_env = {k: v for k, v in env.items() if k != "PYTHONPATH"}
    p = subprocess.run([sys.executable, str(script), json.dumps(runs), site], capture_output=True, text=True,
                       env=cluster_env, cwd=tmp_path, timeout=1800)
    out = [json.loads(ln[len("RESULT "):]) for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
    assert len(out) == 2, p.stdout[-3000:] + p.stderr[-3000:]
    assert [o["rc"] for o in out] == [0, 0], out
    print("cluster runs, wall s:", {Path(o["app"]).name: o["wall_s"] for o in out})  # CI time accounting (-rP)
    _check_recording(str(rec), src)
    _check_rover(str(rover_rec))


ACTOR_PIDS = textwrap.dedent('''
    import json, sys
    import ray
    from aerodaas.clusters.local import enable_token_auth
    from aerodaas.clusters.loopback import loopback_only
    enable_token_auth(); loopback_only()
    ray.init(address=sys.argv[1], logging_level="error")
    from ray.util.state import list_actors
    print("ACTORS " + json.dumps([{"name": a.name, "pid": a.pid, "state": a.state}
                                  for a in list_actors(detail=True, limit=1000)]))
''')


def _warm_idle_pids(daemon_pid: int, ready_dir) -> dict[int, str]:
    """The idle Python workers of the `aerodaas up` daemon's raylet whose setup hook has run (Ray titles a worker
    ray::IDLE when it connects, before its hook imports the framework): pid -> the shared libraries they mapped."""
    import psutil

    from aerodaas.clusters.warm_pool import hook_done

    out = {}
    for p in psutil.Process(daemon_pid).children(recursive=True):
        try:
            if p.cmdline()[:1] == ["ray::IDLE"] and hook_done(ready_dir, p.pid, p.create_time()):
                out[p.pid] = "\n".join(m.path for m in p.memory_maps())
        except (psutil.Error, IndexError):
            continue
    return out


@pytest.mark.cluster
def test_the_example_app_runs_attached_to_aerodaas_up_in_its_warm_workers(installed, tmp_path):
    """`aerodaas up` keeps warm workers: idle Ray workers, bound to no job yet, that imported the framework when
    they started (their memory maps hold onnxruntime's library). A run attached to it places its actors in them:
    Ray's state API gives each actor's pid, and each was an idle warm worker before the run. The user's plug-ins,
    outside the framework (installed where the cluster's interpreter finds them, so not shipped), reach those
    workers and do their job (the recording)."""
    src, env = installed
    env = {k: v for k, v in env.items() if k != "AERODAAS_NO_ATTACH"}
    env["AERODAAS_STATE_DIR"] = str(tmp_path / "state")
    up = _aerodaas(["up", "--cpus", "2", "--warm-workers", "8"], env, tmp_path, timeout=300)
    assert up.returncode == 0 and "8 warm workers" in up.stdout, up.stdout + up.stderr
    state = tmp_path / "state" / "cluster.json"
    st = json.loads(state.read_text())
    try:
        warm: dict[int, str] = {}
        for _ in range(600):  # the pool fills (each worker imports the framework first); bounded, not timed
            st = json.loads(state.read_text())
            warm = _warm_idle_pids(st["pid"], tmp_path / "state" / "warm_hook" / "ready")
            if st.get("warm_idle", 0) >= 8 and len(warm) >= 8:
                break
            time.sleep(0.2)
        assert len(warm) >= 8 and st.get("warm_error") is None, (warm.keys(), st)
        assert all("onnxruntime" in maps for maps in warm.values()), "a warm worker did not import the framework"
        rec = tmp_path / "gas.mcap"
        p = _aerodaas(["run", str(src / "app" / "gas_survey.py"), "--record", str(rec), "--quiet", "--timeout",
                       "300"], env, tmp_path, timeout=600)
        assert p.returncode == 0, (p.stdout + p.stderr)[-4000:]
        assert "attached to the local cluster" in p.stderr, p.stderr[-2000:]
        _check_recording(str(rec), src)
        q = subprocess.run([sys.executable, "-c", ACTOR_PIDS, st["address"]], capture_output=True, text=True,
                           env=env, cwd=tmp_path, timeout=180)
        line = next((ln for ln in q.stdout.splitlines() if ln.startswith("ACTORS ")), None)
        assert line, q.stdout[-2000:] + q.stderr[-3000:]
        actors = [a for a in json.loads(line[len("ACTORS "):]) if a["name"]]
        assert actors, actors
        assert all(a["pid"] in warm for a in actors), (actors, sorted(warm))
    finally:
        d = _aerodaas(["down"], env, tmp_path)
    assert d.returncode == 0 and "stopped" in d.stdout, d.stdout + d.stderr


@pytest.mark.e2e
def test_a_plugin_sensor_is_in_the_live_view_channel_for_channel(gas_run):
    """The live view picks up a plug-in sensor from its declaration, as the recorder does: Foxglove's own npm client
    (tests/js/count_channels.mjs), connected for the whole run of the example app, gets `/uav/gas` with the plug-in's
    schema name and exactly as many messages on every channel as the recording holds; the gas_plume analytics'
    outputs with their schema names, and its plume_entered / plume_left events among the drone's, each as
    recorded."""
    from tests.liveview.test_liveview_npm_client import _recorded_counts

    rc, console, rec, got, no_client = gas_run
    if got is None:
        skip_or_fail(no_client)
    assert rc == 0, "".join(console)[-4000:]
    # the analytics' typed outputs and its events reach Foxglove's client as they reach the recording
    assert got["channels"]["/uav/gas_plume"]["schemaName"] == "aerodaas_example_plugins.PlumeStatus", got["channels"]
    assert got["channels"]["/uav/gas_plume/crossing"]["schemaName"] == "aerodaas_example_plugins.PlumeCrossing"
    live = [e for e in map(json.loads, got["messages"]["/uav/events"]) if e.get("analytics") == "gas_plume"]
    recorded_events = [m for topic, _, _, m in read_messages(str(rec))
                       if topic == "/uav/events" and m.get("analytics") == "gas_plume"]
    assert [e["event"] for e in live] == ["plume_entered", "plume_left"] and live == recorded_events, \
        (live, recorded_events)
    recorded = _recorded_counts(rec)
    assert recorded.get("/uav/gas", 0) >= 20, recorded
    assert got["counts"] == recorded, (got["statuses"], got["counts"], recorded)
    assert got["channels"]["/uav/gas"]["schemaName"] == "aerodaas_example_plugins.GasReading", got["channels"]
