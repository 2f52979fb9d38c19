"""Errors of the application refused before Ray as a user meets them: ``aerodaas plan`` /
``aerodaas run`` on an app file written here, exit 2, a message naming the value, and no Ray session (a fresh
``RAY_TMPDIR`` stays empty, no Ray process names it). ``deploy("edge")`` (a name, not a compute resource), a plug-in
whose ``Config`` is not a pydantic model (registered in the app, or named by an import path in the environment file)
and a syntax error in the app file each failed after Ray started, as "a bug: please report it" (exit 1). Item 3:
``--record`` never overwrites the environment file the app opens itself (``Environment("x.json")``), with
``--overwrite`` too, as with ``--env``."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from aerodaas.plugins import SensorPlugin, registry

from tests.inputs.cli_inprocess import run_cli
from tests.inputs.test_app_value import _ray_processes_under, fresh_ray_tmp

APP = """from aerodaas import *
env = Environment("env.json")
drone = env.get_robot_by_id("d1")
{body}
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=1, y=0, z=2)]))
drone.start_mission()
"""

#: a plug-in module next to the app, named by import path in the environment file
PLUGIN_MODULE = textwrap.dedent("""
    from aerodaas.backends.sim import SimBackend
    from aerodaas.plugins import SensorPlugin


    class GasSensor(SensorPlugin):
        Config = 5

        def sample(self, state, t):
            return None


    class WindBackend(SimBackend):
        Config = dict
""")

APP_SENSOR = textwrap.dedent("""
    from aerodaas.plugins import SensorPlugin, register_sensor


    @register_sensor
    class Gas(SensorPlugin):
        name = "gas"
        Config = {"rate_hz": 1.0}

        def sample(self, state, t):
            return None
""")


def _write(tmp_path, body: str = "", app_text: str | None = None, robot: dict | None = None):
    (tmp_path / "env.json").write_text(json.dumps({"robots": [{"id": "d1", **(robot or {})}],
                                                   "compute": [{"id": "edge", "tier": "edge"}]}))
    (tmp_path / "my_plugins.py").write_text(PLUGIN_MODULE)
    app = tmp_path / "app.py"
    app.write_text(app_text if app_text is not None else APP.format(body=body))
    return app


def _cli(tmp_path, command: str, app, *extra: str, own_process: bool = False):
    """``aerodaas COMMAND APP EXTRA`` (in ``tmp_path``) with a new empty RAY_TMPDIR: in this process
    (:func:`tests.inputs.cli_inprocess.run_cli`, which fails the test if Ray is started), or with ``own_process`` as the
    real command in a subprocess."""
    ray_tmp = fresh_ray_tmp(tmp_path)
    args = [command, str(app), *extra] + (["--quiet"] if command == "run" else ["--json"])
    env = {**os.environ, "RAY_TMPDIR": str(ray_tmp)}
    if not own_process:
        return run_cli(*args, cwd=tmp_path, env=env), ray_tmp
    p = subprocess.run([sys.executable, "-m", "aerodaas.cli", *args], capture_output=True, text=True, cwd=tmp_path,
                       env=env, timeout=300)
    return p, ray_tmp


def _refused_before_ray(p, ray_tmp, *said: str) -> None:
    assert p.returncode == 2, p.stdout[-1500:] + p.stderr[-1500:]
    for s in said:
        assert s in p.stderr, p.stderr[-1500:]
    assert "Traceback" not in p.stderr and "a bug" not in p.stderr, p.stderr[-1500:]
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []


@pytest.mark.parametrize("command", ["plan", "run"])
def test_deploy_on_a_name_is_refused_naming_the_analytics_and_the_value(tmp_path, command):
    app = _write(tmp_path, 'MonitoringAnalytics(name="mon").deploy("edge")')
    p, ray_tmp = _cli(tmp_path, command, app)
    _refused_before_ray(p, ray_tmp, "analytics 'mon': deploy() takes one of the environment's compute resources, "
                                    "got str 'edge' (use env.get_compute_resource_by_id('edge'))")


def test_a_compute_set_after_deploy_is_checked_when_the_app_is_loaded(tmp_path):
    app = _write(tmp_path, 'mon = MonitoringAnalytics(name="mon").deploy(env.get_compute_resource_by_id("edge"))\n'
                           'mon.compute = "edge"\nmon.analyse(drone.get_sensor_by_id("stat").get_data_stream())')
    p, ray_tmp = _cli(tmp_path, "plan", app)
    _refused_before_ray(p, ray_tmp, "analytics 'mon': deployed on str 'edge', which is not a compute resource of "
                                    "this environment (it has ['edge'])")


@pytest.mark.parametrize("command", ["plan", "run"])
def test_a_plugin_of_the_app_whose_config_is_not_a_model_is_refused(tmp_path, command):
    app = _write(tmp_path, app_text=APP_SENSOR + APP.format(body=""))
    p, ray_tmp = _cli(tmp_path, command, app)
    _refused_before_ray(p, ray_tmp, "sensor plug-in 'gas' (class aerodaas_app_app.Gas): Config must be a pydantic "
                                    "BaseModel subclass", "got dict {'rate_hz': 1.0}")


@pytest.mark.parametrize("robot,said", [
    ({"sensors": [{"id": "gas", "type": "my_plugins:GasSensor"}]},
     ["robots.0", "sensor 'gas': sensor plug-in 'my_plugins:GasSensor' (class my_plugins.GasSensor): Config must be "
      "a pydantic BaseModel subclass", "got int 5"]),
    ({"backend": "my_plugins:WindBackend"},
     ["robots.0.backend", "backend plug-in 'my_plugins:WindBackend' (class my_plugins.WindBackend): Config must be a "
      "pydantic BaseModel subclass", "got the class builtins.dict, which is not a pydantic BaseModel"]),
], ids=["sensor", "backend"])
def test_a_plugin_named_by_import_path_whose_config_is_not_a_model_is_refused(tmp_path, robot, said):
    app = _write(tmp_path, robot=robot)
    p, ray_tmp = _cli(tmp_path, "run", app)
    _refused_before_ray(p, ray_tmp, *said)


def test_registering_a_config_that_is_not_a_model_fails_at_the_decorator():
    class Bad(SensorPlugin):
        name = "test_bad_config_registry"
        Config = "rate_hz"

        def sample(self, state, t):
            return None

    with pytest.raises(registry.InvalidPlugin, match=r"sensor plug-in 'test_bad_config_registry' \(class .*Bad\): "
                                                     r"Config must be a pydantic BaseModel subclass.*got str 'rate_hz'"):
        registry.register(Bad, "sensor")
    with pytest.raises(registry.UnknownPlugin):
        registry.resolve("sensor", "test_bad_config_registry")
    assert registry.declaration_error(type("NoConfig", (), {}), "analytics", "x") is None


@pytest.mark.parametrize("command", ["plan", "run"])
def test_a_syntax_error_in_the_app_is_bad_input_naming_the_file_and_line(tmp_path, command):
    app = _write(tmp_path, app_text='from aerodaas import *\n\nenv = Environment("env.json"\nx = 1\n')
    # `run` as the real command: its exit code 2 and no Ray session, from the process itself
    p, ray_tmp = _cli(tmp_path, command, app, own_process=command == "run")
    _refused_before_ray(p, ray_tmp, f"application file {str(app)!r}, line 3: not valid Python: SyntaxError: '(' "
                                    f"was never closed", 'env = Environment("env.json"')


def test_a_syntax_error_in_a_module_the_app_imports_stays_the_apps_own_error(tmp_path):
    (tmp_path / "helper_mod.py").write_text("def broken(:\n    pass\n")
    app = _write(tmp_path, app_text="import helper_mod\n")
    p, ray_tmp = _cli(tmp_path, "plan", app)
    assert p.returncode == 1 and "the application" in p.stderr and "helper_mod.py" in p.stderr, p.stderr[-1500:]
    assert list(ray_tmp.iterdir()) == []


@pytest.mark.parametrize("extra", [[], ["--overwrite"]], ids=["plain", "--overwrite"])
def test_record_never_overwrites_the_environment_file_the_app_opens(tmp_path, extra):
    app = _write(tmp_path)
    env = tmp_path / "env.json"
    before = env.read_bytes()
    p, ray_tmp = _cli(tmp_path, "run", app, "--record", str(env), *extra)
    _refused_before_ray(p, ray_tmp, f"--record {str(env)!r} is an input of this run", "a recording never overwrites")
    assert "pass --overwrite" not in p.stderr and env.read_bytes() == before
