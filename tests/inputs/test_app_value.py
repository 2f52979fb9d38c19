"""An application is a value: loading an app file yields its typed graph without Ray or a flight,
``run``, ``plan`` and ``plugins --app`` share that loader (one module name, so one schema name), and the run's
options are passed, never read from a global. ``--address`` to a port that is no Ray cluster fails
fast with exit 2; a long temp path does not keep a local Ray from starting."""
from __future__ import annotations

import dataclasses
import json
import os
import socket
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import psutil
import pytest

from aerodaas.runtime.app_loader import Application, app_module_name, load_app
from aerodaas.runtime.ray_start import RAY_SOCKET_SUFFIX_MAX, SUN_PATH_MAX, ray_temp_dir

from tests.inputs.cli_inprocess import run_cli
from tests.plugins.test_plugin_registry import APP

ROOT = Path(__file__).resolve().parents[2]


def fresh_ray_tmp(tmp_path: Path) -> Path:
    """A new empty folder to be a subprocess's ``RAY_TMPDIR``, short enough that a local Ray would use it (under a
    long pytest path :func:`ray_temp_dir` would pick another one, and a check that it stays empty would be void);
    removed with ``tmp_path``'s own clean-up (a symlink to it is kept there)."""
    d = Path(tempfile.mkdtemp(prefix="adr-", dir="/tmp"))
    (tmp_path / "ray-tmp-link").symlink_to(d)
    assert ray_temp_dir({"RAY_TMPDIR": str(d)}).startswith(str(d))
    return d


#: the app of the plug-in registry's tests (a sensor plug-in written in the app), printing while it is built
PLUGIN_APP = APP.replace("env = Environment(", 'print("building the app")\nenv = Environment(')


def _cli(*args: str, env: dict | None = None, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=300, env=env or dict(os.environ))


def _ray_processes_under(folder: Path) -> list[str]:
    """Ray processes (gcs_server, raylet, workers) whose command line names ``folder`` (their session dir)."""
    out = []
    for p in psutil.process_iter(["cmdline"]):
        cmd = " ".join(p.info.get("cmdline") or [])
        if str(folder) in cmd:
            out.append(cmd[:200])
    return out


@pytest.mark.parametrize("command", ["plugins", "plan"])
def test_plugins_and_plan_of_an_app_never_start_ray(tmp_path, command):
    """`aerodaas plugins --app APP.py` started Ray and flew the mission (its actors died with ModuleNotFoundError,
    exit 0); now it loads the app as `plan` does: exit 0, the app's plug-in listed, no Ray session or process."""
    app = tmp_path / "my_app.py"
    app.write_text(PLUGIN_APP)
    ray_tmp = fresh_ray_tmp(tmp_path)
    env = {**os.environ, "RAY_TMPDIR": str(ray_tmp)}
    args = ["plugins", "--json", "--kind", "sensor", "--app", str(app)] if command == "plugins" else \
        ["plan", str(app), "--json"]
    # `plugins` as the real command (no Ray session or process, from the process itself); `plan` in-process, whose
    # run_cli fails the test if Ray is started
    p = _cli(*args, env=env, cwd=tmp_path) if command == "plugins" else run_cli(*args, env=env, cwd=tmp_path)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    out = json.loads(p.stdout)
    if command == "plugins":
        assert {r["name"]: r["origin"] for r in out}["my_altimeter"] == f"decorator in {app}"
    else:
        node = next(n for n in out["nodes"] if n["id"] == "uav/alt")
        assert node["plugin"] == "my_altimeter -> aerodaas_app_my_app.Level"
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []
    assert "ModuleNotFoundError" not in p.stderr and "Token authentication" not in p.stderr


def test_loading_an_app_is_a_value_without_ray_or_flight(capsys):
    import ray

    was = ray.is_initialized()
    app = load_app(ROOT / "apps" / "farm_survey.py")
    assert isinstance(app, Application) and not app.continues  # `result = drone.start_mission()` ends the file
    assert app.module == "aerodaas_app_farm_survey" and sys.modules[app.module].__file__ == app.path
    assert [r.id for r in app.robots] == ["quadrotor_base"]
    assert [type(a).__name__ for a in app.graph.analytics["quadrotor_base"]] == ["MonitoringAnalytics"]
    assert [m.name for m in app.graph.schedulers["quadrotor_base"].missions()]  # the survey is queued
    assert not hasattr(sys.modules[app.module], "result")  # start_mission() marked the start, returned nothing
    with pytest.raises(dataclasses.FrozenInstanceError):
        app.mission = None  # type: ignore[misc]
    plan = app.plan()
    assert sorted(a.role for a in plan.actors.values()) == ["analytics", "drone", "recorder"]
    assert ray.is_initialized() == was


def test_the_same_module_name_under_every_loader(tmp_path):
    """The app's plug-in sensor had the schema `__main__.Level` under `run` and `aerodaas_plugins_app.Level` under
    `plugins`: now every loader runs the file as one module, named after the file."""
    app = tmp_path / "my_app.py"
    app.write_text(PLUGIN_APP)
    loaded = load_app(app)
    assert app_module_name(app) == loaded.module == "aerodaas_app_my_app"
    from aerodaas.plugins import registry

    cls = registry.resolve("sensor", "my_altimeter").load()
    assert cls.__module__ == loaded.module and cls.schema_name() == "aerodaas_app_my_app.Level"
    node = next(n for n in loaded.plan().nodes.values() if n.id == "uav/alt")
    assert node.plugin == "my_altimeter -> aerodaas_app_my_app.Level"


def test_an_app_that_goes_on_after_its_mission_is_continued_with_the_result(tmp_path, ray_session, run_options):
    """Code after start_mission() runs once that mission flew, with its result; the app's output before the mission
    is shown once (loaded again after the flight, the part already run is silent)."""
    from aerodaas.runtime.driver import run_file

    env = tmp_path / "env.json"
    env.write_text(json.dumps({"robots": [{"id": "d1", "takeoff_altitude": 2.0, "idle_land_s": 0.5}],
                               "simulation": {"speedup": 10.0}}))
    out = tmp_path / "after.txt"
    app = tmp_path / "two_step.py"
    app.write_text(textwrap.dedent(f'''
        from aerodaas import *
        print("before the mission")
        env = Environment({str(env)!r})
        drone = env.get_robot_by_id("d1")
        drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=2, y=0, z=2)]))
        result = drone.start_mission(timeout=120)
        with open({str(out)!r}, "a") as f:
            f.write(result.outcome + "\\n")
    '''))
    assert load_app(app).continues
    results = run_file(str(app), run_options)
    assert [r.outcome for r in results] == ["success"]
    assert out.read_text() == "success\n"  # the code after the mission ran once, with the result


def test_an_address_that_accepts_tcp_but_is_no_ray_cluster_exits_2(tmp_path):
    """A `--address` to a port that accepts TCP but is no Ray GCS hung 821 s in ray.init; now refused (exit 2, the
    address named) by the check before Ray, bounded by its 10 s time-out."""
    app = tmp_path / "app.py"
    app.write_text("from aerodaas import *\n")
    with socket.socket() as srv:  # listens (the kernel completes connections) and never answers
        srv.bind(("127.0.0.1", 0))
        srv.listen(8)
        port = srv.getsockname()[1]
        p = _cli("run", str(app), "--quiet", "--address", f"127.0.0.1:{port}")
    assert p.returncode == 2, p.stderr[-2000:]
    assert f"--address '127.0.0.1:{port}'" in p.stderr and "not a Ray cluster" in p.stderr, p.stderr


def test_a_ray_gcs_passes_the_address_check(ray_session):
    import ray

    from aerodaas.clusters.addresses import check_ray_address

    check_ray_address(ray.get_runtime_context().gcs_address, timeout_s=30.0)  # raises ValueError if refused


def test_the_ray_temp_dir_keeps_socket_paths_within_the_af_unix_limit(tmp_path):
    long_tmp = "/" + "/".join(["a-rather-long-home-directory-name"] * 3)  # 103 bytes: Ray's sockets would not fit
    chosen = ray_temp_dir({"RAY_TMPDIR": long_tmp})
    assert len(chosen) + RAY_SOCKET_SUFFIX_MAX <= SUN_PATH_MAX and os.path.isdir(chosen)
    assert os.stat(chosen).st_uid == os.getuid()
    assert ray_temp_dir({"RAY_TMPDIR": "/tmp"}) == "/tmp/ray"  # Ray's own choice when it fits


@pytest.mark.e2e
def test_a_local_ray_starts_under_a_long_temp_path(tmp_path):
    """A Ray temp directory under a long home path made the raylet's socket path too long and the run unable to
    start: now a local Ray of ours starts, in a temp directory whose socket paths fit."""
    long_tmp = tmp_path / ("x" * 60) / ("y" * 40)
    long_tmp.mkdir(parents=True)
    code = ("from aerodaas.runtime.ray_start import ensure_ray, shutdown_ray\n"
            "import ray\nensure_ray(None)\n"
            "print(ray._private.worker._global_node.get_session_dir_path())\nshutdown_ray()\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                       env={**os.environ, "RAY_TMPDIR": str(long_tmp), "AERODAAS_NO_ATTACH": "1"})
    assert p.returncode == 0, p.stderr[-3000:]
    session = p.stdout.strip().splitlines()[-1]
    assert session.startswith(f"/tmp/aerodaas-ray-{os.getuid()}"), session
    assert len(session + "/sockets/plasma_store") <= SUN_PATH_MAX
