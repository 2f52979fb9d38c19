"""The in-process command line of the bad-input checks (tests/inputs/cli_inprocess.py) answers as the real command
does and leaves nothing behind: the app's module and plug-ins, the environment, the working folder, ``sys.path`` and the
signal handlers are as before, and a command that would start Ray fails the test instead."""
from __future__ import annotations

import json
import os
import signal
import sys

import pytest

from aerodaas.plugins import registry
from tests.inputs.cli_inprocess import RayStartedInProcess, run_cli

APP = """from aerodaas import *
from aerodaas.plugins import SensorPlugin, register_sensor


@register_sensor
class Probe(SensorPlugin):
    name = "inprocess_probe"

    def sample(self, state, t):
        return None


env = Environment("env.json")
drone = env.get_robot_by_id("d1")
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=1, y=0, z={z})]))
drone.start_mission()
"""


def _app(tmp_path, z: float):
    (tmp_path / "env.json").write_text(json.dumps({"robots": [{"id": "d1"}]}))
    app = tmp_path / "probe_app.py"
    app.write_text(APP.format(z=z))
    return app


def _process_state():
    return (dict(os.environ), os.getcwd(), list(sys.path), signal.getsignal(signal.SIGTERM),
            signal.getsignal(signal.SIGINT), "aerodaas_app_probe_app" in sys.modules)


def test_bad_input_answers_as_the_command_and_leaves_the_process_as_it_was(tmp_path):
    before = _process_state()
    p = run_cli("run", _app(tmp_path, 500), "--quiet", cwd=tmp_path, env={**os.environ, "AERODAAS_PROBE": "1"})
    assert p.returncode == 2 and "max_altitude" in p.stderr, p.stderr
    assert _process_state() == before
    with pytest.raises(registry.UnknownPlugin):  # the app's plug-in went with its module
        registry.resolve("sensor", "inprocess_probe")


def test_a_usage_error_is_exit_2_with_argparse_message():
    p = run_cli("run")
    assert p.returncode == 2 and "the following arguments are required: app" in p.stderr


def test_a_command_that_would_start_ray_fails_the_check(tmp_path):
    before = _process_state()
    with pytest.raises(RayStartedInProcess):
        run_cli("run", _app(tmp_path, 2), "--quiet", cwd=tmp_path)
    assert _process_state() == before
