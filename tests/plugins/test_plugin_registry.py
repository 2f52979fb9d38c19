"""The plug-in registry (aerodaas.plugins.registry): one registry for the five kinds, each registration with its
origin; unknown names refused with what is available; a sensor type written in an application (decorator) is
checked, planned and listed without any framework edit. No Ray."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from aerodaas.config import ConfigError, parse_environment_config
from aerodaas.plugins import SensorPlugin, SensorPluginConfig, registry

from tests.inputs.cli_inprocess import run_cli



def test_builtins_of_every_kind_are_listed_with_their_origin():
    rows = {(r["kind"], r["name"]): r for r in registry.describe_all()}
    assert {k for k, _ in rows} == set(registry.KINDS)
    for key in [("backend", "sim"), ("backend", "mavlink"), ("sensor", "camera"), ("analytics", "ObjectDetector"),
                ("trajectory_scheduler", "NearestNeighborScheduler"), ("analytics_scheduler", "DEMS")]:
        assert rows[key]["origin"] == registry.BUILTIN_ORIGIN == "entry point aerodaas (built-in)", rows[key]
    from aerodaas.schedulers.analytics_base import analytics_scheduler_class, analytics_scheduler_names
    from aerodaas.schedulers.analytics_dems import Dems

    assert analytics_scheduler_class("DEMS") is Dems and "EDGE_FIFO" in analytics_scheduler_names()


def test_unknown_name_lists_what_is_available_and_suggests_the_closest():
    with pytest.raises(registry.UnknownPlugin) as e:
        registry.get("analytics_scheduler", "GAINPLAM")
    msg = str(e.value)
    assert "unknown analytics scheduler 'GAINPLAM'" in msg and "(did you mean 'GAINPLAN'?)" in msg
    assert "'EDGE_FIFO' (entry point aerodaas (built-in))" in msg
    with pytest.raises(registry.UnknownPlugin, match="cannot import it"):
        registry.get("backend", "no_such_module_xyz:Backend")
    with pytest.raises(ValueError, match="unknown plug-in kind"):
        registry.get("camera", "x")


def test_a_decorated_class_records_its_file_and_a_second_class_cannot_take_its_name():
    from aerodaas.plugins import register_sensor

    @register_sensor
    class Thermo(SensorPlugin):
        name = "test_thermo_registry"

        def sample(self, state, t):
            return {"t": t}

    e = registry.resolve("sensor", "test_thermo_registry")
    assert e.cls is Thermo and e.origin == f"decorator in {__file__}"
    register_sensor(Thermo)  # the same class again: fine

    class Other(SensorPlugin):
        name = "test_thermo_registry"

    with pytest.raises(ValueError, match="already taken"):
        register_sensor(Other)


def test_an_import_path_resolves_and_is_recorded_as_such():
    cls = registry.get("analytics_scheduler", "aerodaas.schedulers.analytics_baselines:EdgeFifo")
    from aerodaas.schedulers.analytics_baselines import EdgeFifo

    assert cls is EdgeFifo
    e = registry.resolve("analytics_scheduler", "aerodaas.schedulers.analytics_baselines:EdgeFifo")
    assert e.origin == "import path aerodaas.schedulers.analytics_baselines:EdgeFifo"
    cfg = {"robots": [{"id": "d1"}], "analytics_scheduler": {
        "name": "aerodaas.schedulers.analytics_baselines:EdgeFifo",
        "models": {"det": {"deadline_ms": 100, "edge_ms": 5, "cloud_ms": 50, "benefit": 1}}}}
    assert parse_environment_config(cfg).analytics_scheduler.name.endswith(":EdgeFifo")
    cfg["analytics_scheduler"]["name"] = "aerodaas.schedulers.analytics_baselines:EdgeFifoo"
    with pytest.raises(ConfigError, match="analytics_scheduler.name"):
        parse_environment_config(cfg)


def test_sensor_properties_are_checked_against_the_plugins_config_model():
    class Cfg(SensorPluginConfig):
        lo: float = 0.0

    class Probe(SensorPlugin):
        name = "test_probe_props"
        Config = Cfg

    registry.register(Probe)
    good = {"robots": [{"id": "d1", "sensors": [{"id": "p", "type": "test_probe_props", "properties": {"lo": 2}}]}]}
    r = parse_environment_config(good).robots[0]
    assert r.sensors[0].properties == {"rate_hz": 1.0, "lo": 2.0}
    bad = json.loads(json.dumps(good))
    bad["robots"][0]["sensors"][0]["properties"] = {"hi": 1}
    with pytest.raises(ConfigError) as e:
        parse_environment_config(bad)
    assert "sensors.0.properties.hi" in str(e.value) and "'p'" in str(e.value)


APP = textwrap.dedent('''
    from pydantic import BaseModel

    from aerodaas import Environment, NearestNeighborScheduler
    from aerodaas.config import parse_environment_config
    from aerodaas.plugins import SensorPlugin, register_sensor


    class Level(BaseModel):
        robot: str
        level: float


    @register_sensor
    class Altimeter(SensorPlugin):
        name = "my_altimeter"
        Message = Level

        def sample(self, state, t):
            return Level(robot=self.robot_id, level=state.position[2])


    env = Environment(parse_environment_config({
        "robots": [{"id": "uav", "takeoff_altitude": 3.0, "sensors": [{"id": "alt", "type": "my_altimeter"}]}]}))
    env.set_trajectory_scheduler(NearestNeighborScheduler(env))
    env.get_robot_by_id("uav").start_mission()
''')


def test_a_sensor_written_in_the_app_is_planned_and_listed_without_starting_ray(tmp_path):
    app = tmp_path / "my_app.py"
    app.write_text(APP)
    p = run_cli("plan", str(app), "--json", cwd=tmp_path)  # in-process: Ray refused
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    node = next(n for n in json.loads(p.stdout)["nodes"] if n["id"] == "uav/alt")
    assert node["kind"] == "sensor" and node["plugin"] == "my_altimeter -> aerodaas_app_my_app.Level", node
    plug = tmp_path / "plug.py"
    plug.write_text(APP.split("env = Environment")[0])
    p = run_cli("plugins", "--json", "--kind", "sensor", "--app", str(plug), cwd=tmp_path)
    assert p.returncode == 0, p.stderr[-2000:]
    rows = {r["name"]: r for r in json.loads(p.stdout)}
    assert rows["my_altimeter"]["origin"] == f"decorator in {plug}", rows["my_altimeter"]
    assert rows["camera"]["origin"] == registry.BUILTIN_ORIGIN


def test_an_environment_sensor_of_unknown_type_is_refused_not_skipped():
    with pytest.raises(ConfigError) as e:
        parse_environment_config({"robots": [{"id": "d1"}], "env_sensors": [{"id": "x", "type": "camara"}]})
    assert "env_sensors.0.type" in str(e.value) and "'camara'" in str(e.value)


@pytest.mark.e2e
def test_a_sensor_written_in_the_app_flies_and_is_recorded(tmp_path, ray_session):
    """The decorator path on Ray: the app's sensor class (and its pydantic message model) live only in the app,
    travel to the drone actor by value, sample the vehicle state there and are recorded with their schema."""
    from mcap.reader import make_reader

    from aerodaas.recording.reader import read_messages

    app = tmp_path / "my_app.py"
    app.write_text(APP.replace('"sensors": [{"id": "alt", "type": "my_altimeter"}]',
                               '"sensors": [{"id": "alt", "type": "my_altimeter", "properties": {"rate_hz": 5}}], '
                               '"idle_land_s": 1.0').replace(
        'env.get_robot_by_id("uav").start_mission()', textwrap.dedent('''
            from aerodaas import AeroListData, PriorityQueue, Waypoint
            sched = env.trajectory_scheduler()
            d = env.get_robot_by_id("uav")
            d.navigate(sched.generate_navigation(PriorityQueue(AeroListData(
                [Waypoint(id="h", x=0.0, y=0.0, z=3.0, hover_duration=2.0)]), priority=2)))
            env.start_mission([d])''')))
    rec = tmp_path / "run.mcap"
    # in-process on the worker's shared Ray session (the class travels by value as before; checked clean after)
    p = run_cli("run", str(app), "--record", str(rec), "--quiet", "--timeout", "240", cwd=tmp_path, shared_ray=True)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    assert "sensor alt (my_altimeter):" in p.stdout
    levels = [m for t, _, _, m in read_messages(str(rec)) if t == "/uav/alt"]
    assert len(levels) >= 20 and all(m["robot"] == "uav" for m in levels)
    assert max(m["level"] for m in levels) > 2.5 and min(m["level"] for m in levels) < 0.5  # took off, landed
    with open(rec, "rb") as f:
        summary = make_reader(f).get_summary()
    ch = next(c for c in summary.channels.values() if c.topic == "/uav/alt")
    assert summary.schemas[ch.schema_id].name == "aerodaas_app_my_app.Level"  # as `plan` names it
    assert set(json.loads(summary.schemas[ch.schema_id].data)["properties"]) == {"robot", "level"}


def test_a_builtins_name_is_taken_from_the_start_unless_the_registration_says_it_replaces():
    """An app's backend named ``sim`` silently replaced the simulator (the built-ins were registered
    lazily, after it). Now refused naming the built-in, unless ``replaces=True`` / ``plugin_replaces = True``."""
    from aerodaas.backends.sim import SimBackend

    class MySim(SimBackend):
        kind = "sim"

    with pytest.raises(ValueError, match=r"backend name 'sim' is already taken by aerodaas\.backends\.sim:\w+ "
                                         r"\(entry point aerodaas \(built-in\)\).*replaces=True"):
        registry.register(MySim, "backend")
    assert registry.get("backend", "sim") is not MySim

    class Gusty(SimBackend):
        kind = "sim_replacement_test"

    class Replacing(SimBackend):
        kind = "sim_replacement_test"
        plugin_replaces = True

    registry.register(Gusty, "backend")
    registry.register(Replacing, "backend")  # it says so: the later one holds the name
    assert registry.get("backend", "sim_replacement_test") is Replacing


def test_a_plugin_module_that_exits_on_import_is_an_error_naming_it(tmp_path, monkeypatch):
    """A module that calls sys.exit(0) while imported ended runs with exit 0 and no flight."""
    (tmp_path / "exiting_plugin.py").write_text("import sys\nsys.exit(0)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(registry.UnknownPlugin, match=r"module 'exiting_plugin' called sys\.exit\(0\) while being "
                                                      r"imported"):
        registry.get("sensor", "exiting_plugin:Thing")


def test_an_app_whose_import_exits_is_refused_before_ray_naming_the_file(tmp_path):
    import json

    from tests.inputs.test_app_value import _ray_processes_under, fresh_ray_tmp

    ray_tmp = fresh_ray_tmp(tmp_path)
    (tmp_path / "exiting_helper.py").write_text("import sys\n\nsys.exit(0)\n")
    env = tmp_path / "env.json"
    env.write_text(json.dumps({"robots": [{"id": "d1"}]}))
    app = tmp_path / "app.py"
    app.write_text(f"from aerodaas import *\nimport exiting_helper\nenv = Environment({str(env)!r})\n"
                   "drone = env.get_robot_by_id('d1')\nresult = drone.start_mission()\n")
    r = run_cli("run", str(app), "--record", str(tmp_path / "r.mcap"),  # in-process: Ray refused
                env={**__import__("os").environ, "RAY_TMPDIR": str(ray_tmp)})
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert "sys.exit(0) was called in" in r.stderr and "exiting_helper.py line 3" in r.stderr, r.stderr[-2000:]
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []  # no Ray session started


def test_each_builtin_plugin_module_imports_first_in_a_fresh_process():
    """A built-in scheduler module imported first must not load the other built-ins (which import it back,
    half-initialised): a dispatcher actor unpickling a DEMS policy died with 'cannot import name
    CLOUD_TRIGGER_BUFFER_MS from partially initialized module'. The modules: those of the package's own
    analytics-scheduler entry points."""
    import subprocess
    import sys
    from importlib.metadata import distribution

    mods = sorted({ep.value.split(":")[0] for ep in distribution("aerodaas").entry_points
                   if ep.group == "aerodaas.analytics_schedulers"})
    assert len(mods) == 5, mods
    code = "import importlib, sys; importlib.import_module(sys.argv[1])"
    for m in mods:
        r = subprocess.run([sys.executable, "-c", code, m], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, (m, r.stderr[-1500:])


def _declared_entry_points() -> dict[str, dict[str, str]]:
    """``{group: {name: "module:Class"}}`` as this checkout's pyproject.toml declares them."""
    import tomllib
    from pathlib import Path

    doc = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text(encoding="utf-8"))
    return {g: dict(eps) for g, eps in doc["project"]["entry-points"].items() if g.startswith("aerodaas.")}


def test_every_builtin_resolves_through_this_packages_own_entry_points():
    """The built-ins are declared as a user's package declares its plug-ins — entry points in
    pyproject.toml, read from the installed metadata — with no private table. Every built-in the registry knows is
    one of them, every one resolves (its class a subclass of its kind's base), and the installed metadata is what
    pyproject.toml declares (an install that predates an edit of the entry points fails here)."""
    from importlib.metadata import distribution

    declared = _declared_entry_points()
    installed: dict[str, dict[str, str]] = {}
    for ep in distribution("aerodaas").entry_points:
        if ep.group.startswith("aerodaas."):
            installed.setdefault(ep.group, {})[ep.name] = ep.value
    assert installed == declared and set(declared) == set(registry.ENTRY_POINT_GROUPS.values())
    kind_of_group = {g: k for k, g in registry.ENTRY_POINT_GROUPS.items()}
    for group, eps in declared.items():
        kind = kind_of_group[group]
        for name, target in eps.items():
            e = registry.resolve(kind, name)
            assert (e.builtin, e.dist, e.origin, e.target) == (True, "aerodaas", registry.BUILTIN_ORIGIN, target), e
            assert issubclass(registry.get(kind, name), registry.kind_base(kind))
    builtins = {(e.kind, e.name) for e in registry.entries() if e.builtin}
    assert builtins == {(kind_of_group[g], n) for g, eps in declared.items() for n in eps}
    assert sum(map(len, declared.values())) == 36  # 4 backends, 3 sensors, 7 analytics, 3 + 14 schedulers, 5 frame sources


def test_a_plugin_cannot_take_a_builtins_name_in_a_fresh_process():
    """A clash between a plug-in and a built-in is refused from the first registration of the process, before
    anything asked for a built-in (the built-ins' names come from the metadata, nothing imported): a sensor called
    ``camera`` and an analytics scheduler called ``DEMS``, each naming the built-in it collides with."""
    code = textwrap.dedent('''
        import sys
        from aerodaas.plugins import SensorPlugin, register_sensor
        from aerodaas.schedulers.analytics_base import AnalyticsScheduler, register_analytics_scheduler

        class MyCamera(SensorPlugin):
            name = "camera"

        class MyDems(AnalyticsScheduler):
            name = "DEMS"

        for register, cls in ((register_sensor, MyCamera), (register_analytics_scheduler, MyDems)):
            try:
                register(cls)
            except ValueError as e:
                print(e)
            else:
                print("registered", cls.__name__)
        ''')
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.strip().splitlines()
    assert len(lines) == 2 and "registered" not in r.stdout, r.stdout
    assert ("sensor name 'camera' is already taken by aerodaas.plugins.builtin_sensors:CameraSensor "
            "(entry point aerodaas (built-in))") in lines[0]
    assert ("analytics scheduler name 'DEMS' is already taken by aerodaas.schedulers.analytics_dems:Dems "
            "(entry point aerodaas (built-in))") in lines[1]


def test_no_private_table_of_builtins_remains():
    """Built-ins go through the registry like any plug-in: no ``_BUILTIN_TARGETS`` or ``_BUILTIN_MODULES`` table."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    hits = [str(p) for d in ("aerodaas", "actors", "schedulers", "clusters") for p in (root / d).rglob("*.py")
            if "_BUILTIN_TARGETS" in p.read_text(encoding="utf-8") or "_BUILTIN_MODULES" in p.read_text(encoding="utf-8")]
    assert hits == []


def test_an_install_without_the_packages_entry_points_is_an_error_saying_how_to_install():
    """The built-ins come only from the installed metadata: when it declares none (a checkout imported without
    installing it, or entry points edited without re-installing), asking for any plug-in says so and how to fix it,
    instead of 'unknown backend sim'. A fresh process whose metadata reader finds nothing of ours."""
    code = textwrap.dedent('''
        from aerodaas.plugins import registry

        def nothing_installed(builtin):
            return []

        registry._distribution_entry_points = nothing_installed
        try:
            registry.resolve("backend", "sim")
        except registry.MissingBuiltins as e:
            print("MissingBuiltins:", e)
        ''')
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.startswith("MissingBuiltins:") and "pip install -e ." in r.stdout, r.stdout


def test_resolving_a_builtin_in_a_fresh_process_reads_this_packages_metadata_alone():
    """A fresh process (a driver building its app, a Ray worker setting up a drone on ``sim``) that
    resolves a built-in reads only this package's entry points; every other installed distribution is scanned only
    for a name that is not a built-in (then once)."""
    code = textwrap.dedent('''
        from aerodaas.plugins import registry
        e = registry.resolve("backend", "sim")
        first = (e.builtin, registry.REGISTRY.builtins_loaded, registry.REGISTRY.entry_points_loaded)
        try:
            registry.resolve("backend", "no-such-backend")
        except registry.UnknownPlugin:
            pass
        print(first, registry.REGISTRY.entry_points_loaded)
    ''')
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[0] == "(True, True, False) True"
