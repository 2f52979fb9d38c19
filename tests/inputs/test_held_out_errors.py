"""Held-out errors: each ends before Ray with exit 2 naming the field. (a) a plug-in class that is
not a subclass of its kind's base (``"trajectory_scheduler": "subprocess:Popen"`` was accepted when the app set
its own scheduler and constructed as ``Popen(env)`` otherwise); (b) a plug-in whose ``Config`` validator raises
something other than ValueError (a TypeError gave a traceback); (c) a camera replaying a file that is not MCAP, or
an MCAP file without its topic (refused by the camera actor, after Ray had started); (d) a MAVLink connection
string that cannot be one (``tcp:999.1.1.1:99999`` reached the drone actor)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from aerodaas.config import ConfigError, parse_environment_config
from aerodaas.plugins import registry

from tests.inputs.cli_inprocess import run_cli
from tests.inputs.test_app_value import _ray_processes_under, fresh_ray_tmp

#: a sensor plug-in and a backend plug-in whose Config validators raise TypeError (pydantic passes it on as is)
PLUGINS = textwrap.dedent('''
    from pydantic import field_validator
    from aerodaas.backends.sim import SimBackend
    from aerodaas.plugins import SensorPlugin, SensorPluginConfig
    from aerodaas.config.backends import SimConfig


    class RateConfig(SensorPluginConfig):
        rate_hz: float = 1.0

        @field_validator("rate_hz")
        @classmethod
        def _typed(cls, v):
            raise TypeError("rate_hz must be a Fraction")


    class Gauge(SensorPlugin):
        name = "gauge"
        Config = RateConfig


    class PickyConfig(SimConfig):
        gain: float = 1.0

        @field_validator("gain")
        @classmethod
        def _typed(cls, v):
            raise TypeError("gain must be a Fraction")


    class PickySim(SimBackend):
        kind = "picky_sim"
        Config = PickyConfig
''')

APP = textwrap.dedent('''
    from aerodaas import *
    env = Environment("env.json")
    drone = env.get_robot_by_id("d1")
    {scheduler}
    drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=1, y=0, z=2)]))
    drone.start_mission()
''')


def _env(robot: dict | None = None, **top) -> dict:
    return {"robots": [{"id": "d1", **(robot or {})}], "compute": [{"id": "edge", "tier": "edge"}], **top}


def _not_mcap(tmp_path) -> str:
    p = tmp_path / "notes.mcap"
    p.write_text("field notes, not a recording")
    return str(p)


def _mcap_without_the_topic(tmp_path) -> str:
    from aerodaas.recording.writer import McapRecorder

    p = tmp_path / "other.mcap"
    with McapRecorder(p) as rec:
        rec.write_image("/other/camera/cam", 1, np.zeros((8, 8, 3), np.uint8))
    return str(p)


def _camera(source_file: str) -> dict:
    return {"sensors": [{"id": "cam", "type": "camera", "properties": {"source": "mcap", "mcap": source_file}}]}


#: (case id, environment from tmp_path, what the app does about its scheduler, what stderr must name)
CASES = [
    ("scheduler-class-not-a-scheduler-app-sets-its-own",
     lambda tmp: _env(trajectory_scheduler="subprocess:Popen"),
     "env.set_trajectory_scheduler(NearestNeighborScheduler(env))",
     "trajectory_scheduler: Value error, trajectory scheduler plug-in 'subprocess:Popen' (class subprocess.Popen) "
     "is not a subclass of aerodaas.schedulers.base.TrajectoryScheduler"),
    ("scheduler-class-not-a-scheduler",
     lambda tmp: _env(trajectory_scheduler="subprocess:Popen"), "",
     "trajectory_scheduler: Value error, trajectory scheduler plug-in 'subprocess:Popen'"),
    ("sensor-config-validator-raises-typeerror",
     lambda tmp: _env({"sensors": [{"id": "g", "type": "held_out_plugins:Gauge", "properties": {"rate_hz": 2.0}}]}),
     "", "sensors.0.properties (sensor type 'held_out_plugins:Gauge'): the settings were refused by the plug-in's "
         "Config (held_out_plugins.RateConfig): TypeError: rate_hz must be a Fraction"),
    ("camera-mcap-not-mcap", lambda tmp: _env(_camera(_not_mcap(tmp))), "",
     "robots.0.sensors.0.properties.mcap: "),
    ("camera-mcap-without-the-topic", lambda tmp: _env(_camera(_mcap_without_the_topic(tmp))), "",
     "robots.0.sensors.0.properties.topic: '/d1/camera/cam' is not a channel with messages"),
    ("mavlink-connection-out-of-range",
     lambda tmp: _env({"backend": "mavlink", "mavlink": {"connection": "tcp:999.1.1.1:99999"}}), "",
     "mavlink.connection: Value error, 'tcp:999.1.1.1:99999': port '99999' is not within [1, 65535]"),
]


@pytest.mark.parametrize("case,make_env,scheduler,said", CASES, ids=[c[0] for c in CASES])
def test_a_held_out_error_ends_before_ray_with_exit_2_naming_the_field(tmp_path, case, make_env, scheduler, said):
    (tmp_path / "held_out_plugins.py").write_text(PLUGINS)
    (tmp_path / "env.json").write_text(json.dumps(make_env(tmp_path)))
    app = tmp_path / "app.py"
    app.write_text(APP.format(scheduler=scheduler))
    ray_tmp = fresh_ray_tmp(tmp_path)
    env = {**os.environ, "RAY_TMPDIR": str(ray_tmp), "PYTHONPATH": str(tmp_path)}
    if case == CASES[0][0]:  # the real command: its exit code 2 and no Ray session, from the process itself
        p = subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", str(app), "--quiet"], capture_output=True,
                           text=True, cwd=tmp_path, timeout=300, env=env)
    else:  # the same code path in this process (which fails the test if Ray is started)
        p = run_cli("run", str(app), "--quiet", cwd=tmp_path, env=env)
    assert p.returncode == 2, p.stdout[-2000:] + p.stderr[-2000:]
    assert said in p.stderr, p.stderr[-2000:]
    assert "Traceback" not in p.stderr, p.stderr[-3000:]
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []  # no Ray session was started


@pytest.mark.parametrize("kind", registry.KINDS)
def test_a_class_that_is_not_of_its_kinds_base_is_refused_for_every_kind(kind):
    with pytest.raises(registry.InvalidPlugin, match=rf"plug-in 'subprocess:Popen' \(class subprocess.Popen\) is "
                                                     rf"not a subclass of {registry.KIND_BASES[kind].replace(':', '.')}"):
        registry.get(kind, "subprocess:Popen")
    for e in registry.entries(kind):  # every plug-in there is (built-in, installed) is one of its kind's
        assert registry.base_error(e.load(), kind, e.name) is None, (kind, e.name)


def test_a_backend_config_validator_raising_typeerror_is_the_backends_configuration_error(tmp_path, monkeypatch):
    (tmp_path / "held_out_plugins.py").write_text(PLUGINS)
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ConfigError, match=r"robots\.0: Value error, backend_config \(backend "
                                          r"'held_out_plugins:PickySim'\): the settings were refused by the plug-in's "
                                          r"Config \(held_out_plugins\.PickyConfig\): TypeError: gain must be"):
        parse_environment_config(_env({"backend": "held_out_plugins:PickySim",
                                       "backend_config": {"gain": 2.0}}))


@pytest.mark.parametrize("conn", ["tcp:127.0.0.1:5760", "udpin:0.0.0.0:14550", "udp:localhost:14550",
                                  "udpout:192.168.1.20:14550", "tcpin:0.0.0.0:5760", "/dev/ttyACM0", "COM3"])
def test_connection_strings_pymavlink_takes_are_accepted(conn):
    from aerodaas.config.backends import check_mavlink_connection

    check_mavlink_connection(conn)


@pytest.mark.parametrize("conn,why", [("tcp:999.1.1.1:5760", "host '999.1.1.1' is not an IPv4 address"),
                                      ("tcp:127.0.0.1:0", "port '0' is not within"),
                                      ("tcp:127.0.0.1:99999", "port '99999' is not within"),
                                      ("tcp:bad_host:5760", "host 'bad_host' is not an IPv4 address or a host name"),
                                      ("serial0", "is not a MAVLink connection"),
                                      ("http:127.0.0.1:80", "is not a MAVLink connection"),
                                      ("tcp:127.0.0.1", "is not a MAVLink connection")])
def test_connection_strings_that_cannot_be_one_are_refused(conn, why):
    from aerodaas.config.backends import check_mavlink_connection

    with pytest.raises(ValueError, match=why):
        check_mavlink_connection(conn)
