"""Input cases that are not one environment field, for ``python -m aerodaas.reliability``:

* values an application gives the API (``Waypoint(x="1")``, ``y=True``, a yaw rate of 1e308), an empty navigation,
  a pre-planned mission above ``max_queued_items``, a NaN waypoint built with ``model_construct``: ``aerodaas run``
  exits 2 naming the field, before Ray starts;
* items built without validation handed to the safety gate itself (it checks every value again);
* plug-in modules that do not import (a missing module, an exception or ``sys.exit`` while imported, a syntax error,
  a missing class) and plug-ins whose ``Config`` is not a pydantic model (by import path, or registered in the
  app): refused naming the field, the plug-in, the class and the error;
* errors of the application itself that AeroDaaS refuses before Ray (exit 2): ``deploy("edge")`` (a name, not a
  compute resource) and a syntax error in the app file (named with its line);
* output paths that are the run's own inputs (the application, its environment file, also when the app opens it
  and ``--overwrite`` is given) or a device;
* a WPL file numbered out of sequence, and ``aerodaas inject`` values that start with '-'.

Each row: ``{"kind", "category", "name", "refused", "message"}`` as in
:func:`aerodaas.reliability.catalogue.run_inputs` (``refused``: refused, or answered, as documented)."""
from __future__ import annotations

import contextlib
import copy
import io
import json
import sys
import uuid
from pathlib import Path
from typing import Any, Callable

import numpy as np

from aerodaas import cli
from aerodaas.config import ConfigError, RobotConfig, parse_environment_config
from aerodaas.missionfile import MissionFileError, load_mission
from aerodaas.model.types import VelocityCommand, Waypoint
from aerodaas.navigation.safety import SafetyGate, SafetyViolation
from aerodaas.recording.writer import McapRecorder
from aerodaas.reliability.cli_cases import _app, base_env, run_cli_cases
from aerodaas.tools import hitl_client

__all__ = ["APP_VALUE_CASES", "OUTPUT_PATH_CASES", "PLUGIN_MODULES", "plugin_cases", "run_app_cases"]

_APP = """
from aerodaas import *
env = Environment({env!r})
drone = env.get_robot_by_id("d1")
{body}
drone.start_mission()
"""


def _app_body(body: str) -> Callable[[Path], list[str]]:
    """argv of ``aerodaas run`` for an application that navigates with ``body`` (its environment: one drone)."""
    return lambda t: [_app(t, _APP.format(env=str(t / "cli_env.json"), body=body))]


def _nav(items: str) -> str:
    return f"drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, {items}))"


_NAN_WP = ('Waypoint.model_construct(id="n", x=float("nan"), y=0.0, z=2.0, hover_duration=0.0, '
           'waypoint_type="relative", speed=None, acceptance_radius=0.3)')

def _app_timeout(value: str) -> Callable[[Path], list[str]]:
    """argv of ``aerodaas run`` for a one-waypoint application calling ``drone.start_mission(timeout=<value>)``."""
    text = _APP.format(env="{env}", body=_nav('[Waypoint(id="a", x=1, y=0, z=2)]'))
    text = text.replace("drone.start_mission()", f"drone.start_mission(timeout={value})")
    return lambda t: [_app(t, text.replace("'{env}'", repr(str(t / "cli_env.json"))))]


#: (name, argv after ``run``, expected exit code, text the message must contain, category)
APP_VALUE_CASES: list[tuple[str, Callable[[Path], list[str]], int, str, str]] = [
    ('Waypoint(x="1") (a string)', _app_body(_nav('[Waypoint(id="a", x="1", y=0, z=2)]')), 2, "got str '1'",
     "strict types"),
    ("Waypoint(y=True) (a boolean)", _app_body(_nav('[Waypoint(id="a", x=1, y=True, z=2)]')), 2, "got bool",
     "strict types"),
    ('PriorityQueue(nav, priority="1")',
     _app_body('drone.navigate(PriorityQueue(AeroNavigation(NavigationType.DISTANCE_DRIVEN, '
               '[Waypoint(id="a", x=1, y=0, z=2)]), priority="1"))'), 2, "priority", "strict types"),
    ("VelocityCommand(yaw_rate=1e308)", _app_body(_nav("[VelocityCommand(yaw_rate=1e308)]")), 2, "yaw_rate",
     "bounds / cross-field"),
    ("an empty navigation", _app_body(_nav("[]")), 2, "holds no waypoints", "app-level errors"),
    ("start_mission(timeout=-1)", _app_timeout("-1"), 2, "start_mission(timeout=...) must be a number of "
     "wall-clock seconds within (0, 1e+07], got -1", "bounds / cross-field"),
    ('start_mission(timeout="60") (a string)', _app_timeout('"60"'), 2, "start_mission(timeout=...) must be a "
     "number of wall-clock seconds within (0, 1e+07], got str '60'", "strict types"),
    ("50,000 pre-planned waypoints (max_queued_items 5000)",
     _app_body(_nav('[Waypoint(id=f"w{i}", x=i % 50, y=i // 50 % 50, z=2) for i in range(50000)]')), 2,
     "max_queued_items", "app-level errors"),
    ("a NaN waypoint built with model_construct", _app_body(_nav(f"[{_NAN_WP}]")), 2, "not a valid Waypoint",
     "app-level errors"),
    ('analytics.deploy("edge") (a name, not a compute resource)',
     _app_body('MonitoringAnalytics(name="mon").deploy("edge")'), 2, "analytics 'mon': deploy() takes one of the "
     "environment's compute resources, got str 'edge'", "app-level errors"),
    ('an analytics whose compute was set to "edge" after deploy()',
     _app_body('mon = MonitoringAnalytics(name="mon").deploy(env.get_compute_resources()[0])\nmon.compute = "edge"\n'
               'mon.analyse(drone.get_sensor_by_id("stat").get_data_stream())\n'
               + _nav('[Waypoint(id="a", x=1, y=0, z=2)]')), 2,
     "analytics 'mon': deployed on str 'edge', which is not a compute resource of this environment",
     "app-level errors"),
    ("a syntax error in the application file", lambda t: [_app(t, "from aerodaas import *\nenv = Environment(\n")], 2,
     "line 2: not valid Python: SyntaxError", "app-level errors"),
    ("trajectory_scheduler 'subprocess:Popen' in environment.json, the app setting its own scheduler",
     lambda t: [_app(t, _APP.format(env=str(t / "cli_env.json"), body="env.set_trajectory_scheduler("
                     "NearestNeighborScheduler(env))\n" + _nav('[Waypoint(id="a", x=1, y=0, z=2)]')),
                env={"robots": [{"id": "d1"}], "trajectory_scheduler": "subprocess:Popen"})], 2,
     "trajectory scheduler plug-in 'subprocess:Popen' (class subprocess.Popen) is not a subclass of "
     "aerodaas.schedulers.base.TrajectoryScheduler", "plug-in imports"),
    ("a plug-in sensor of the app whose Config is a dict",
     lambda t: [_app(t, "from aerodaas.plugins import SensorPlugin, register_sensor\n\n\n@register_sensor\n"
                        "class Gas(SensorPlugin):\n    name = 'gas'\n    Config = {'rate_hz': 1.0}\n\n"
                        "    def sample(self, state, t):\n        return None\n")], 2,
     "sensor plug-in 'gas' (class aerodaas_app_cli_app.Gas): Config must be a pydantic BaseModel subclass",
     "plug-in imports"),
]


def _record_into(which: str, *extra: str) -> Callable[[Path], list[str]]:
    def make(t: Path) -> list[str]:
        app = _app(t)  # its environment file: opened by the app itself (Environment(path)), no --env
        target = {"app": app, "env": str(t / "cli_env.json"), "null": "/dev/null"}[which]
        return [app, "--record", target, *extra]
    return make


def _record_into_named(kind: str) -> Callable[[Path], list[str]]:
    """argv of ``aerodaas run --record F --overwrite`` where F is a file the environment names: the ground image
    (``ground``) or a recorded camera's MCAP, itself a recording of ours (``camera``)."""
    def make(t: Path) -> list[str]:
        if kind == "ground":
            import cv2  # lazy: heavy dependency (OpenCV)

            target = t / "ground.png"
            cv2.imwrite(str(target), np.full((32, 32, 3), 90, np.uint8))
            env: dict[str, Any] = {"robots": [{"id": "d1"}], "world": {"ground": {"image": target.name}}}
        else:
            target = t / "camera.mcap"
            with McapRecorder(target) as rec:
                rec.write_image("/d1/camera/cam", 1, np.zeros((8, 8, 3), np.uint8))
            env = {"robots": [{"id": "d1", "sensors": [{"id": "cam", "type": "camera", "properties": {
                "source": "mcap", "mcap": target.name}}]}]}
        return [_app(t, env=env), "--record", str(target), "--overwrite"]
    return make


_INPUT = "is an input of this run"
#: ``--record`` given the run's own inputs or a device: (name, argv after ``run``, exit code, text, category)
OUTPUT_PATH_CASES: list[tuple[str, Callable[[Path], list[str]], int, str, str]] = [
    ("--record names the application itself", _record_into("app"), 2, _INPUT, "output paths"),
    ("--record names the environment file", _record_into("env"), 2, _INPUT, "output paths"),
    ("--record names the environment file the app opens, with --overwrite", _record_into("env", "--overwrite"), 2,
     _INPUT, "output paths"),
    ("--record /dev/null", _record_into("null"), 2, "not a regular file", "output paths"),
    ("--record names the environment's ground image, with --overwrite", _record_into_named("ground"), 2,
     "is an input of this run (world.ground.image of the environment", "output paths"),
    ("--record names a recorded camera's MCAP (a recording of ours), with --overwrite", _record_into_named("camera"),
     2, "is an input of this run (robots.0.sensors.0.properties.mcap of the environment", "output paths"),
]

#: plug-in modules written for the plug-in cases: stem -> source
PLUGIN_MODULES = {
    "raises": "raise ZeroDivisionError('division by zero at import')\n",
    "exits": "import sys\nsys.exit(0)\n",
    "syntax": "def broken(:\n    pass\n",
    "empty": "X = 1\n",
    "badconfig": ("from aerodaas.backends.sim import SimBackend\nfrom aerodaas.plugins import SensorPlugin\n\n\n"
                  "class GasSensor(SensorPlugin):\n    Config = 5\n\n    def sample(self, state, t):\n"
                  "        return None\n\n\nclass Backend(SimBackend):\n    Config = dict\n"),
    # Config validators raising TypeError (pydantic passes anything but ValueError/AssertionError on as it is)
    "typeerror": ("from pydantic import field_validator\nfrom aerodaas.backends.sim import SimBackend\n"
                  "from aerodaas.config.backends import SimConfig\n"
                  "from aerodaas.plugins import SensorPlugin, SensorPluginConfig\n\n\n"
                  "class RateConfig(SensorPluginConfig):\n    rate_hz: float = 1.0\n\n"
                  "    @field_validator('rate_hz')\n    @classmethod\n    def _typed(cls, v):\n"
                  "        raise TypeError('rate_hz must be a Fraction')\n\n\n"
                  "class GasSensor(SensorPlugin):\n    Config = RateConfig\n\n\n"
                  "class GainConfig(SimConfig):\n    gain: float = 1.0\n\n"
                  "    @field_validator('gain')\n    @classmethod\n    def _typed(cls, v):\n"
                  "        raise TypeError('gain must be a Fraction')\n\n\n"
                  "class Backend(SimBackend):\n    Config = GainConfig\n"),
}


def plugin_cases(tag: str) -> list[tuple[str, Callable[[dict], None], str]]:
    """(name, edit of a valid environment, text the error must contain) naming plug-ins in the modules of
    :data:`PLUGIN_MODULES` written as ``aerodaas_case_<stem>_<tag>`` (``tag``: unique per run, so that no module is
    cached from a previous run)."""
    def mod(stem: str) -> str:
        return f"aerodaas_case_{stem}_{tag}"

    def robot(d: dict) -> dict:
        return d["robots"][0]

    return [
        ("backend from a module that does not exist",
         lambda d: robot(d).update(backend=f"no_such_module_{tag}:Backend"), "ModuleNotFoundError"),
        ("backend from a module raising ZeroDivisionError when imported",
         lambda d: robot(d).update(backend=f"{mod('raises')}:Backend"), "ZeroDivisionError"),
        ("backend from a module calling sys.exit(0) when imported",
         lambda d: robot(d).update(backend=f"{mod('exits')}:Backend"), "sys.exit"),
        ("sensor type from a module with a syntax error",
         lambda d: robot(d)["sensors"].append({"id": "gas", "type": f"{mod('syntax')}:GasSensor"}), "SyntaxError"),
        ("trajectory_scheduler naming a class its module lacks",
         lambda d: d.update(trajectory_scheduler=f"{mod('empty')}:Planner"), "AttributeError"),
        ("sensor type whose Config is 5 (not a pydantic model)",
         lambda d: robot(d)["sensors"].append({"id": "gas", "type": f"{mod('badconfig')}:GasSensor"}),
         "Config must be a pydantic BaseModel subclass, the model of its settings (subclass aerodaas.plugins."
         "SensorPluginConfig), or None; got int 5"),
        ("backend whose Config is dict (not a pydantic model)",
         lambda d: robot(d).update(backend=f"{mod('badconfig')}:Backend"),
         "Config must be a pydantic BaseModel subclass, the model of its settings, or None; got the class "
         "builtins.dict"),
        # a class that is not of its kind's base (subprocess.Popen was constructed as Popen(env))
        ("trajectory_scheduler 'subprocess:Popen' (a class, not a TrajectoryScheduler)",
         lambda d: d.update(trajectory_scheduler="subprocess:Popen"),
         "trajectory_scheduler: Value error, trajectory scheduler plug-in 'subprocess:Popen' (class subprocess.Popen) "
         "is not a subclass of aerodaas.schedulers.base.TrajectoryScheduler"),
        ("backend 'subprocess:Popen' (a class, not a VehicleBackend)",
         lambda d: robot(d).update(backend="subprocess:Popen"),
         "is not a subclass of aerodaas.backends.base.VehicleBackend"),
        ("sensor type 'subprocess:Popen' (a class, not a SensorPlugin)",
         lambda d: robot(d)["sensors"].append({"id": "gas", "type": "subprocess:Popen"}),
         "is not a subclass of aerodaas.plugins.sensor.SensorPlugin"),
        ("analytics_scheduler 'subprocess:Popen' (a class, not an AnalyticsScheduler)",
         lambda d: d.update(analytics_scheduler={"name": "subprocess:Popen"}),
         "analytics_scheduler.name: Value error, analytics scheduler plug-in 'subprocess:Popen' (class "
         "subprocess.Popen) is not a subclass of aerodaas.schedulers.analytics_base.AnalyticsScheduler"),
        ("sensor type whose Config validator raises TypeError",
         lambda d: robot(d)["sensors"].append({"id": "gas", "type": f"{mod('typeerror')}:GasSensor",
                                              "properties": {"rate_hz": 2.0}}),
         "sensors.2.properties (sensor type 'aerodaas_case_typeerror_"),
        ("backend whose Config validator raises TypeError",
         lambda d: robot(d).update(backend=f"{mod('typeerror')}:Backend", backend_config={"gain": 2.0}),
         "the settings were refused by the plug-in's Config (aerodaas_case_typeerror_"),
    ]


def _plugin_rows(tmp: Path) -> list[dict[str, Any]]:
    tag = uuid.uuid4().hex[:8]
    folder = tmp / f"plugins_{tag}"
    folder.mkdir()
    for stem, text in PLUGIN_MODULES.items():
        (folder / f"aerodaas_case_{stem}_{tag}.py").write_text(text)
    rows = []
    sys.path.insert(0, str(folder))
    try:
        for name, edit, expect in plugin_cases(tag):
            d = copy.deepcopy(base_env())
            edit(d)
            try:
                parse_environment_config(json.loads(json.dumps(d)), source="case")
                ok, msg = False, "accepted"
            except ConfigError as e:
                ok, msg = expect in str(e) and "Traceback" not in str(e), str(e)
            rows.append({"kind": "environment", "category": "plug-in imports", "name": name, "refused": ok,
                         "message": msg})
    finally:
        sys.path.remove(str(folder))
    return rows


def _wpl_row(tmp: Path) -> dict[str, Any]:
    rows = ["QGC WPL 110", "0\t1\t0\t16\t0\t0\t0\t0\t47.3977\t8.5456\t488\t1"]
    rows += [f"{seq}\t0\t3\t16\t0\t0\t0\t0\t47.3978\t8.5456\t20\t1" for seq in (1, 1, 5)]
    p = tmp / "numbered_1_1_5.waypoints"
    p.write_text("\n".join(rows) + "\n")
    try:
        load_mission(p)
        ok, msg = False, "accepted (renumbered)"
    except MissionFileError as e:
        ok, msg = "line 4" in str(e) and "seq 1 out of order" in str(e), str(e)
    return {"kind": "mission file", "category": "mission files", "name": "QGC WPL numbered 1, 1, 5", "refused": ok,
            "message": msg}


def _gate_rows() -> list[dict[str, Any]]:
    r = RobotConfig.model_validate({"id": "r"})
    gate = SafetyGate(r.safety, r.limits, r.home)
    rows = []
    for name, item, field in [
        ("a NaN waypoint built with model_construct",
         Waypoint.model_construct(id="n", x=float("nan"), y=0.0, z=2.0, hover_duration=0.0, waypoint_type="relative",
                                  speed=None, acceptance_radius=0.3), "x"),
        ('a waypoint whose z was set to "5" without validation', Waypoint(id="s", x=1, y=0, z=2).model_copy(
            update={"z": "5"}), "z"),
        ("a velocity command with yaw_rate 1e308 built with model_construct",
         VelocityCommand.model_construct(id="v", vx=0.0, vy=0.0, vz=0.0, yaw_rate=1e308, duration=0.5,
                                         issued_at=None), "yaw_rate"),
    ]:
        try:
            gate.check_item(item, (0.0, 0.0, 2.0), (0.0, 0.0, 0.0))
            rows.append({"kind": "safety gate", "category": "safety gate", "name": name, "refused": False,
                         "message": "accepted"})
        except SafetyViolation as e:
            rows.append({"kind": "safety gate", "category": "safety gate", "name": name,
                         "refused": e.field == field, "message": str(e)})
    return rows


def _inject_rows() -> list[dict[str, Any]]:
    """``aerodaas inject`` with a token and a waypoint that start with '-' (argparse read them as options: about one
    token in 64 failed): the request must carry them as given. The HTTP call is captured, not sent."""
    token = "-" + "t0k3n" * 5
    sent: list = []
    saved = hitl_client.request
    hitl_client.request = lambda method, path, body=None, **kw: (sent.append((path, body, kw)) or (200, {"added": ["w"]}))
    rows = []
    try:
        for name, argv, check in [
            ("inject --token starting with '-'", ["--token", token, "--waypoint", "1,2,3"],
             lambda b, kw: kw.get("token") == token),
            ("inject --waypoint -3,-2,5 (south-west of home)", ["--token", "a" * 24, "--waypoint", "-3,-2,5"],
             lambda b, kw: b["waypoints"] == [{"x": -3.0, "y": -2.0, "z": 5.0}]),
        ]:
            sent.clear()
            err = io.StringIO()
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                try:
                    code = cli.main(["inject", "--drone", "d1", "--url", "http://127.0.0.1:9", *argv])
                except SystemExit as e:  # argparse's refusal
                    code = int(e.code or 0)
            ok = code == 0 and len(sent) == 1 and check(sent[0][1], sent[0][2])
            rows.append({"kind": "command line", "category": "command line", "name": name, "refused": ok,
                         "message": f"exit {code}: " + (f"sent {sent[0][1]}" if sent else err.getvalue().strip()[:200])})
    finally:
        hitl_client.request = saved
    return rows


def run_app_cases(tmp: Path) -> list[dict[str, Any]]:
    """Every case of this module (files written under ``tmp``)."""
    rows = []
    for name, make, code, expect, category in APP_VALUE_CASES + OUTPUT_PATH_CASES:
        rows += run_cli_cases([(name, make, code, expect)], category)
    rows += _plugin_rows(tmp)
    rows.append(_wpl_row(tmp))
    rows += _gate_rows()
    rows += _inject_rows()
    return rows
