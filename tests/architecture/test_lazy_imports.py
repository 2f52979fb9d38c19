"""Start-up cost kept out of processes that do not need it: the heavy third-party libraries are
imported only where they are used. Each check imports a module in a fresh interpreter and reads ``sys.modules``
(what Python itself loaded), so no wall-clock time is involved.

- ``aerodaas.cli`` (every ``aerodaas`` command starts with it) imports no heavy library: the public API of
  ``aerodaas/__init__.py`` is resolved on first use (PEP 562), not at ``import aerodaas``.
- An actor module, imported as a Ray worker imports it (after ``ray``), imports none of the libraries its actor does
  not use: the recorder no OpenCV and no onnxruntime, the drone actor no onnxruntime, none of them matplotlib, PyAV
  or FastAPI.
- A Ray worker's setup hook and Ray's serialisation add-ons import none of the add-ons' libraries, nor Pydantic.
- A run without the human-in-the-loop API does not import its server (FastAPI) on the driver.
- A drone actor's start imports only the third-party packages it uses and adds at most a set amount of memory to a
  bare Ray worker's, both measured in the same test (memory, not time).
"""
from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

#: libraries that cost a start tens to hundreds of milliseconds of CPU each (``python -X importtime``)
HEAVY = ("onnxruntime", "cv2", "matplotlib", "av", "mcap", "fastapi", "pydantic", "numpy", "scipy", "shapely",
         "PIL", "ray")


def _loaded_after(module: str, before: str = "") -> set[str]:
    """The heavy libraries of :data:`HEAVY` in ``sys.modules`` of a fresh interpreter after it imported
    ``before`` (statements) and then ``module``. Raises AssertionError with the child's stderr if it fails."""
    code = textwrap.dedent(f"""
        import sys
        {before}
        import {module}
        print(" ".join(m for m in {HEAVY!r} if m in sys.modules))
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return set(r.stdout.split())


def test_the_command_line_imports_no_heavy_library():
    assert _loaded_after("aerodaas.cli") == set()


def test_the_public_api_is_complete_and_resolved_on_use():
    """``from aerodaas import *`` yields every name of ``__all__``, aliases included, and an unknown name is an
    AttributeError naming it."""
    code = textwrap.dedent("""
        import sys
        import aerodaas
        assert "aerodaas.app.api" not in sys.modules, "import aerodaas built the API"
        ns = {}
        exec("from aerodaas import *", ns)
        missing = sorted(set(aerodaas.__all__) - set(ns))
        assert not missing, missing
        from aerodaas.app.api import Environment
        from aerodaas.schedulers import TrajectoryScheduler
        assert ns["Environment"] is Environment and ns["IEnvironment"] is Environment
        assert ns["INavigate"] is TrajectoryScheduler and ns["AeroNav"] is ns["AeroNavigation"]
        try:
            aerodaas.NoSuchName
        except AttributeError as e:
            assert "NoSuchName" in str(e), e
        else:
            raise AssertionError("no AttributeError")
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]


#: a fresh interpreter started as a Ray worker is: AeroDaaS's setup hook, then Ray's serialisation add-ons applied
#: (as on the worker's first message, ``aerodaas.clusters.worker_memory``)
_HOOKED_WORKER = textwrap.dedent("""
    import sys
    import ray
    from ray.util import serialization_addons
    from aerodaas.clusters.worker_memory import worker_setup

    class Context:
        def _register_cloudpickle_serializer(self, *a, **k): pass
        def _register_cloudpickle_reducer(self, *a, **k): pass

    worker_setup()
    serialization_addons.apply(Context())
""")


@pytest.mark.parametrize("module, unused", [
    ("aerodaas.actors.recording.actor", {"cv2", "onnxruntime", "matplotlib", "av", "fastapi", "pydantic", "scipy"}),
    ("aerodaas.actors.host.drone_actor", {"onnxruntime", "matplotlib", "av", "fastapi"}),
    ("aerodaas.actors.host.analytics_actor", {"matplotlib", "av", "fastapi", "mcap"}),
])
def test_an_actor_module_imports_only_what_its_actor_uses(module, unused):
    loaded = _loaded_after(module, before="import ray")
    assert not loaded & unused, f"{module} imported {sorted(loaded & unused)}"


def test_a_ray_workers_setup_hook_imports_none_of_the_addons_libraries():
    """A Ray worker's start as AeroDaaS sets it up (the setup hook, then Ray's serialisation add-ons on its first
    message, ``aerodaas.clusters.worker_memory``) imports none of the libraries the add-ons serve, nor Pydantic (Ray's
    ``pydantic_compat``, which only the Pydantic add-on needs, imports it): a worker whose actor never uses it, an
    idle one or the recorder of an unrecorded run, does not pay for it."""
    code = _HOOKED_WORKER + textwrap.dedent("""
        print(" ".join(m for m in ("pydantic", "pyarrow", "starlette", "anyio", "ray._common.pydantic_compat")
                       if m in sys.modules))
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == []


def test_a_run_without_hitl_does_not_import_its_server():
    """The driver's HITL step with the API off returns None without importing ``aerodaas.tools.hitl``."""
    code = textwrap.dedent("""
        import sys
        from types import SimpleNamespace
        from aerodaas.runtime import driver
        run = SimpleNamespace(env=SimpleNamespace(cfg=SimpleNamespace(hitl=SimpleNamespace(enabled=False))),
                              opts=SimpleNamespace(hitl=None))
        assert driver._start_hitl(run) is None
        print(" ".join(m for m in ("fastapi", "aerodaas.tools.hitl") if m in sys.modules))
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == []


def test_an_unrecorded_runs_actor_sets_up_without_the_recorders_writer_or_live_view():
    """The drone actor of a run that is not recorded builds its components (a fresh interpreter, as
    a fresh Ray worker does) without importing the MCAP writer, the recorder service or the live view (57 modules,
    0.04 s of CPU per actor measured); a recorded one still gets them (see tests/recording)."""
    code = textwrap.dedent("""
        import sys
        from aerodaas import Environment
        from aerodaas.actors.host.assembly import ActorAssembly
        from aerodaas.actors.data.plane import DataPlane
        from aerodaas.bench.fleet import fleet_config
        from aerodaas.config import SimulationConfig, parse_environment_config
        from aerodaas.runtime.dataflow import build_plan
        from aerodaas.runtime.preflight import robot_schedulers

        env = Environment(parse_environment_config(fleet_config(1, fps=10.0, width=160, height=120)))
        robots = env.get_env_robots()
        plan = build_plan(env, robots, {r.id: [] for r in robots}, robot_schedulers(env, robots), SimulationConfig())
        (hid,) = [h for h, a in plan.actors.items() if a.role == "drone"]
        assert plan.actors[hid].spec.record is None and not plan.actors[hid].spec.record_remote
        rt = ActorAssembly(DataPlane(hid, "edge", 0, workers=2), plan.actors[hid].spec)
        assert rt.drones and rt.recorder is None
        print(" ".join(m for m in ("mcap", "aerodaas.actors.recording.recorder", "aerodaas.liveview.server") if m in sys.modules))
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == []


def test_a_refused_application_is_reported_without_ray_or_the_actors(tmp_path):
    """``aerodaas run`` of an application its checks refuse (a waypoint below the safety floor) exits 2 naming the
    value without having imported Ray, OpenCV, any actor module or rich (the progress display, imported only for a
    terminal's progress: 0.1 s of every run's start): the built-in actors reach the runtime as a source
    (:data:`aerodaas.actors.builtin.source.BUILTIN`) it loads only once the input passed (0.4 CPU-s less per refusal, about
    a third, measured with ``/usr/bin/time``); a good application still gets them (every run test)."""
    from tests.conftest import REPO

    apps = REPO / "apps"
    src = (apps / "farm_survey.py").read_text()
    assert "z=1.5" in src  # else the run below would not be refused: it would fly
    (tmp_path / "farm_survey.json").write_text((apps / "farm_survey.json").read_text())
    (tmp_path / "low.py").write_text(src.replace("z=1.5", "z=-3"))
    (tmp_path / "good.py").write_text(src)
    # refused while the app loads (its waypoint), and refused by the run's checks of the options (--record names
    # one of its inputs), which come after the app was loaded and just before the actors would be
    for args, says in ((["low.py"], ("z=-3.0", "min_altitude")), (["good.py", "--record", "farm_survey.json"],
                                                                   ("farm_survey.json",))):
        code = textwrap.dedent(f"""
            import sys
            from aerodaas.cli import main
            rc = main(["run", *{args!r}])
            print(rc, " ".join(m for m in ("ray", "cv2", "aerodaas.actors.builtin.catalogue", "rich") if m in sys.modules))
        """)
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path)
        assert r.returncode == 0, r.stderr[-2000:]
        assert all(s in r.stderr for s in says), r.stderr[-2000:]
        assert r.stdout.split() == ["2"], (args, r.stdout)


#: what no drone actor of a simulated fleet imports (the libraries and the modules of ours cut from its path; a
#: colocated analytics brings its hosting back, the rest stays out): Ray's serialisation add-ons for libraries no actor
#: uses (Arrow, Pydantic's v1 package, Starlette and anyio; ``aerodaas.clusters.worker_memory``), the dispatcher's
#: analytics scheduling, the video stream readers, the live view and the recorder's writer, the built-in analytics
#: (the benchmark's own needs only their base), the driver's side, the heavy libraries no drone of it uses, and the
#: tracker with its geo-location and track colours (only an analytics that tracks records tracks)
DRONE_ACTOR_DENIED = ("pyarrow", "pydantic.v1", "starlette", "anyio", "aerodaas.actors.dispatch",
                      "aerodaas.schedulers.dispatch", "aerodaas.video.reader", "aerodaas.video.source",
                      "aerodaas.video.discovery", "aerodaas.liveview", "aerodaas.recording.writer",
                      "aerodaas.analytics.core", "aerodaas.analytics.detector", "aerodaas.analytics.follow",
                      "aerodaas.app", "aerodaas.runtime", "aerodaas.bench.fleet", "onnxruntime", "av", "mcap", "rich",
                      "scipy", "matplotlib", "shapely", "torch", "fastapi", "PIL", "aerodaas.perception", "colorsys")
#: what a drone actor without analytics does not import besides: their hosting
NO_ANALYTICS_DENIED = ("aerodaas.actors.analytics",)

#: a Ray worker's start of a drone actor, in a fresh interpreter: the setup hook, the serialisation context's add-ons
#: (as on the worker's first message), the actor's class (Ray imports its module), the recorder actor's class (its
#: ``ray.get_actor`` loads it), then the actor's constructor builds its components from the driver's pickled spec
_DRONE_WORKER = _HOOKED_WORKER + textwrap.dedent("""
    from ray import cloudpickle
    import aerodaas.actors.host.drone_actor
    import aerodaas.actors.recording.actor
    from aerodaas.actors.data.plane import DataPlane
    from aerodaas.actors.host.assembly import ActorAssembly

    hid, spec = cloudpickle.loads(open(sys.argv[1], "rb").read())
    rt = ActorAssembly(DataPlane(hid, "edge", 0, workers=2), spec)
    assert len(rt.drones) == 1, rt.drones
    deny = sys.argv[2].split(",")
    print("analytics", len(rt.analytics), "cameras", len(rt.drones[0].cameras))
    print(" ".join(sorted(m for m in sys.modules if any(m == d or m.startswith(d + ".") for d in deny))))
""")


@pytest.mark.parametrize("colocated", [True, False], ids=["fleet-benchmark-drone", "drone-without-analytics"])
def test_a_drone_actor_imports_none_of_what_its_path_does_not_use(tmp_path, colocated):
    """A drone actor of ``aerodaas bench fleet`` (its exposure analytics colocated) and one whose analytics run
    elsewhere, started as a Ray worker starts them (:data:`_DRONE_WORKER`), hold none of :data:`DRONE_ACTOR_DENIED`
    in ``sys.modules`` (the second none of :data:`NO_ANALYTICS_DENIED` either), and their actor is built: with the
    analytics and the camera it analyses when colocated (a camera without a consumer is not built)."""
    import dataclasses

    from ray import cloudpickle

    from aerodaas import Environment
    from aerodaas.bench.fleet import build_fleet, fleet_config
    from aerodaas.config import SimulationConfig, parse_environment_config
    from aerodaas.runtime.dataflow import build_plan, collect_graph
    from aerodaas.runtime.preflight import robot_schedulers

    env = build_fleet(1)[0] if colocated else Environment(parse_environment_config(fleet_config(1)))
    robots = env.get_env_robots()
    graphs = {r.id: collect_graph(r) if colocated else [] for r in robots}
    plan = build_plan(env, robots, graphs, robot_schedulers(env, robots), SimulationConfig())
    (hid,) = [h for h, a in plan.actors.items() if a.role == "drone"]
    spec = dataclasses.replace(plan.actors[hid].spec, record_remote=None)  # its recorder is an actor of the run
    (tmp_path / "spec.pkl").write_bytes(cloudpickle.dumps((hid, spec)))
    deny = DRONE_ACTOR_DENIED + (() if colocated else NO_ANALYTICS_DENIED)
    r = subprocess.run([sys.executable, "-c", _DRONE_WORKER, str(tmp_path / "spec.pkl"), ",".join(deny)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    lines = r.stdout.splitlines()
    assert lines[0] == f"analytics {int(colocated)} cameras {int(colocated)}", r.stdout
    assert lines[1:] == [""], f"the drone actor imported {lines[1:]}"


#: the third-party packages a drone actor of ``aerodaas bench fleet`` holds beyond a bare AeroDaaS Ray worker: the
#: frames (numpy, OpenCV), the messages and configuration (Pydantic), geodetic conversions (pymap3d, which imports
#: dateutil)
DRONE_ACTOR_LIBRARIES = {"numpy", "cv2", "pydantic", "pydantic_core", "annotated_types", "typing_inspection",
                         "pymap3d", "dateutil"}
#: the memory a drone actor's start may add to a bare worker's, MiB of anonymous memory (Python objects, malloc
#: arenas, the libraries' writable data): ``docs/results/fleet.md`` has what it holds per library, about 24 MiB;
#: this bound leaves a quarter more
DRONE_START_BUDGET_MIB = 30.0

#: printed at the end of a worker's start: its anonymous memory (``/proc/self/smaps_rollup``, KiB) and the
#: top-level packages it imported from a site-packages folder
_MEMORY_AND_LIBRARIES = textwrap.dedent("""
    import gc
    gc.collect()
    anon = [int(l.split()[1]) for l in open("/proc/self/smaps_rollup") if l.startswith("Anonymous:")][0]
    libs = {n for n, m in list(sys.modules.items()) if "." not in n and "site-packages" in (getattr(m, "__file__", None) or "")}
    print("memory", anon, " ".join(sorted(libs)))
""")


def test_a_drone_actors_start_holds_its_memory_and_library_budget(tmp_path):
    """A drone actor of ``aerodaas bench fleet`` started as a Ray worker starts it (:data:`_DRONE_WORKER`) against a
    bare AeroDaaS Ray worker (Ray, the setup hook and Ray's add-ons: :data:`_HOOKED_WORKER`), each in a fresh
    interpreter: it imports no third-party package but :data:`DRONE_ACTOR_LIBRARIES`, and its anonymous memory
    exceeds the bare worker's by at most :data:`DRONE_START_BUDGET_MIB`. Memory, not time: the same on a loaded
    machine."""
    import dataclasses

    from ray import cloudpickle

    from aerodaas.bench.fleet import build_fleet
    from aerodaas.config import SimulationConfig
    from aerodaas.runtime.dataflow import build_plan, collect_graph
    from aerodaas.runtime.preflight import robot_schedulers

    env = build_fleet(1)[0]
    robots = env.get_env_robots()
    plan = build_plan(env, robots, {r.id: collect_graph(r) for r in robots}, robot_schedulers(env, robots),
                      SimulationConfig())
    (hid,) = [h for h, a in plan.actors.items() if a.role == "drone"]
    spec = dataclasses.replace(plan.actors[hid].spec, record_remote=None)
    (tmp_path / "spec.pkl").write_bytes(cloudpickle.dumps((hid, spec)))
    out = {}
    for name, code in (("bare", _HOOKED_WORKER), ("drone", _DRONE_WORKER)):
        r = subprocess.run([sys.executable, "-c", code + _MEMORY_AND_LIBRARIES, str(tmp_path / "spec.pkl"), "none"],
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr[-3000:]
        (line,) = [ln for ln in r.stdout.splitlines() if ln.startswith("memory ")]
        _, kib, *libs = line.split()
        out[name] = (int(kib) / 1024.0, set(libs))
    extra_libs = out["drone"][1] - out["bare"][1]
    assert extra_libs <= DRONE_ACTOR_LIBRARIES, f"a drone actor imports {sorted(extra_libs - DRONE_ACTOR_LIBRARIES)}"
    assert {"numpy", "cv2"} <= extra_libs, extra_libs  # else the bare worker is not bare: the check measures nothing
    extra_mib = out["drone"][0] - out["bare"][0]
    assert extra_mib <= DRONE_START_BUDGET_MIB, f"a drone actor's start adds {extra_mib:.1f} MiB to a bare worker's"
