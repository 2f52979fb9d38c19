"""What a drone actor loads: no library it does not use. Read from outside the actor, in the
kernel's list of the worker process's mappings (``/proc/<pid>/maps``): an imported extension module maps its shared
library."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from tests.conftest import skip_or_fail
from tests.runtime.test_dataplane import _env

#: libraries that no drone actor of a simulated fleet uses: Ray's Arrow reducers (imported by Ray's serialisation
#: context unless aerodaas.clusters.worker_memory.worker_setup runs), the detector's runtime, plotting, PyTorch,
#: the geofence's geometry (Shapely: these drones have no geofence)
UNUSED = ("pyarrow", "onnxruntime", "matplotlib", "torch", "shapely")


def _mapped_packages(pid: int) -> set[str]:
    """Top-level packages under site-packages with a file mapped into ``pid``."""
    out = set()
    for line in Path(f"/proc/{pid}/maps").read_text().splitlines():
        path = line.split(None, 5)[5] if len(line.split(None, 5)) > 5 else ""
        if "site-packages/" in path:
            out.add(path.split("site-packages/", 1)[1].split("/", 1)[0].split(".libs")[0].lower())
    return out


#: what the recorder actor of a run that is not recorded uses none of: the MCAP writer's libraries (OpenCV, NumPy,
#: Pydantic's core), besides :data:`UNUSED`
RECORDER_UNUSED = UNUSED + ("cv2", "opencv", "numpy", "pydantic_core")


def test_a_drone_actor_maps_no_library_it_does_not_use(ray_session, run_options):
    """The drone actor of an unrecorded run maps none of :data:`UNUSED`; the run's recorder actor, which has no
    file to write, none of :data:`RECORDER_UNUSED` either (read once both are set up and the mission flies)."""
    import ray

    env = _env(1)
    run_options.run_id = "imports1"
    seen: dict = {}

    def look(robot) -> None:
        for actor in ("drone/d00", "recorder"):
            pid = ray.get(ray.get_actor(f"aerodaas/{run_options.run_id}/{actor}").ping.remote())
            seen[actor] = _mapped_packages(pid)

    env.get_robot_by_id("d00").on_mission_start(look)
    res = env.start_mission(timeout=2.0, options=run_options)
    assert set(res.robots) == {"d00"}
    pkgs = seen["drone/d00"]
    assert any(p.startswith(("cv2", "opencv")) for p in pkgs), pkgs  # the renderer's OpenCV: the reading works
    assert "ray" in pkgs, pkgs
    assert not [p for p in pkgs if p.startswith(UNUSED)], pkgs
    rec = seen["recorder"]
    assert "ray" in rec and not [p for p in rec if p.startswith(RECORDER_UNUSED)], rec


#: modules an actor of a run never needs: the detector's runtime, PyTorch, plotting, Arrow, the terminal display,
#: the MCAP writer (only the recorder actor writes), and the driver's side (application API, runtime, benchmarks)
DRIVER_SIDE = ("onnxruntime", "torch", "matplotlib", "pyarrow", "rich", "mcap", "aerodaas.app", "aerodaas.runtime",
               "aerodaas.bench.fleet")


def test_the_actor_modules_import_nothing_of_the_driver_side():
    """A fresh interpreter imports what a drone actor of the fleet benchmark runs — the drone and analytics actor
    classes, the assembly their setup builds, the benchmark's colocated analytics — and none of
    :data:`DRIVER_SIDE` is then in ``sys.modules`` (``aerodaas.bench.fleet_analytics`` is not
    ``aerodaas.bench.fleet``)."""
    import subprocess

    code = ("import sys\n"
            "import aerodaas.actors.host.drone_actor, aerodaas.actors.host.analytics_actor, aerodaas.actors.host.assembly\n"
            "import aerodaas.bench.fleet_analytics\n"
            f"print(sorted(m for m in sys.modules if any(m == d or m.startswith(d + '.') for d in {DRIVER_SIDE!r})))\n"
            "print('cv2' in sys.modules, 'aerodaas.actors.host.assembly' in sys.modules)\n")
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.splitlines() == ["[]", "True True"], out.stdout


def test_drone_and_analytics_actors_run_opencv_on_one_thread_by_default(ray_session, run_options):
    """``actor_opencv_threads`` (default 1): the drone actor (its renderer and colocated analytics) and an analytics
    actor report OpenCV's thread count of their own process (``cv2.getNumThreads()``) as 1, whatever the cores."""
    import ray

    from tests.runtime.test_dataplane import FrameProbe

    env = _env(1)
    probe = FrameProbe()
    probe.deploy(env.get_compute_resource_by_id("edge"))  # an analytics actor of its own
    probe.analyse(env.get_robot_by_id("d00").get_sensor_by_id("cam").get_data_stream())
    run_options.run_id = "cvthreads1"
    seen: dict = {}

    def look(robot) -> None:
        for name in ("drone/d00", "analytics/edge/probe#1"):
            seen[name] = ray.get(ray.get_actor(f"aerodaas/{run_options.run_id}/{name}").describe.remote())

    env.get_robot_by_id("d00").on_mission_start(look)
    res = env.start_mission(timeout=2.0, options=run_options)
    assert set(res.robots) == {"d00"}
    assert {k: v["opencv_threads"] for k, v in seen.items()} == {"drone/d00": 1, "analytics/edge/probe#1": 1}, seen


@pytest.mark.parametrize("threads", [None, 3])
def test_actor_opencv_threads_reaches_the_actors_opencv(threads):
    """The environment's ``actor_opencv_threads`` is the drone actor's OpenCV pool (built in this process: no Ray);
    null leaves OpenCV's own setting alone."""
    import cv2

    from tests.runtime.test_dataplane import _host_for

    before = cv2.getNumThreads()
    env = _env(1)
    env.cfg.actor_opencv_threads = threads
    try:
        cv2.setNumThreads(2)
        host, _rt, plan = _host_for(env)
        host.close()
        assert {a.spec.opencv_threads for a in plan.actors.values()} == {threads}
        assert cv2.getNumThreads() == (2 if threads is None else threads)
    finally:
        cv2.setNumThreads(before)


def test_actor_opencv_threads_must_be_a_positive_count():
    from aerodaas.bench.fleet import fleet_config
    from aerodaas.config import ConfigError, parse_environment_config

    with pytest.raises((ConfigError, ValueError), match="actor_opencv_threads"):
        parse_environment_config({**fleet_config(1), "actor_opencv_threads": 0})


class _Context:
    """Ray's serialisation context as its add-ons see it: records what they register."""

    def __init__(self) -> None:
        self.registered: list[str] = []

    def _register_cloudpickle_reducer(self, cls, *args, **kwargs) -> None:
        self.registered.append(f"{cls.__module__}.{cls.__name__}")

    def _register_cloudpickle_serializer(self, cls, *args, **kwargs) -> None:
        self.registered.append(f"{cls.__module__}.{cls.__name__}")


def test_the_setup_hook_keeps_arrow_out_until_something_imports_it():
    """In a fresh interpreter (pyarrow not imported yet): Ray's add-ons after the hook register nothing of Arrow and
    import nothing; once the process imports pyarrow itself, they register the Arrow reducers as before."""
    import subprocess

    code = ("import sys\n"
            "from aerodaas.clusters.worker_memory import worker_setup\n"
            "from tests.runtime.test_worker_imports import _Context\n"
            "from ray.util import serialization_addons\n"
            "worker_setup()\n"
            "c = _Context(); serialization_addons.apply(c)\n"
            "print('pyarrow' in sys.modules, any('pyarrow' in r for r in c.registered))\n"
            "import pyarrow\n"
            "c = _Context(); serialization_addons.apply(c)\n"
            "print(any(r.startswith('pyarrow') for r in c.registered))\n")
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False", "True"], out.stdout


@pytest.mark.parametrize("library, registered", [("pydantic.v1.fields", "pydantic.v1.fields.ModelField"),
                                                  ("starlette.datastructures", "starlette.datastructures.State")])
def test_the_setup_hook_keeps_rays_other_addons_out_until_something_imports_them(library, registered):
    """Pydantic's v1 package and Starlette as Arrow above: after the hook Ray's add-ons neither import nor register
    them; once the process imports the library itself, its reducer is registered as before."""
    import subprocess

    code = ("import sys\n"
            "from aerodaas.clusters.worker_memory import worker_setup\n"
            "from tests.runtime.test_worker_imports import _Context\n"
            "from ray.util import serialization_addons\n"
            "worker_setup()\n"
            "c = _Context(); serialization_addons.apply(c)\n"
            f"print({library!r} in sys.modules, {registered!r} in c.registered)\n"
            f"import {library}\n"
            "c = _Context(); serialization_addons.apply(c)\n"
            f"print({registered!r} in c.registered)\n")
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False", "True"], out.stdout


#: numpy's OpenBLAS's thread count, read from the loaded library (numpy's wheels ship it as ``scipy_openblas``;
#: an OpenBLAS of the system exports ``openblas_get_num_threads``); "none" when numpy links another BLAS
_BLAS_THREADS = """
import ctypes, numpy
libs = [l.split()[-1] for l in open("/proc/self/maps") if "openblas" in l.lower() and ".so" in l]
names = ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads", "openblas_get_num_threads64_",
         "openblas_get_num_threads")
fns = [getattr(ctypes.CDLL(p), n, None) for p in libs[:1] for n in names]
print(next((f() for f in fns if f is not None), "none"))
"""


@pytest.mark.parametrize("user_value, threads", [(None, "1"), ("2", "2")], ids=["default", "the-users-own"])
def test_the_setup_hook_gives_openblas_one_thread_unless_the_user_chose(user_value, threads):
    """After the hook, the OpenBLAS numpy loads runs one thread (no pool of one thread per core in every worker);
    an ``OPENBLAS_NUM_THREADS`` the user set is kept."""
    import os
    import subprocess

    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if user_value is not None:
        env["OPENBLAS_NUM_THREADS"] = user_value
    code = "from aerodaas.clusters.worker_memory import worker_setup\nworker_setup()\n" + _BLAS_THREADS
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    if out.stdout.split() == ["none"]:
        skip_or_fail("numpy here does not link OpenBLAS")
    assert out.stdout.split() == [threads], out.stdout


def test_a_runs_driver_creates_actors_without_importing_arrow(tmp_path):
    """The driver's side (``aerodaas.runtime.ray_start.init_ray``, a fresh local Ray as ``aerodaas run`` starts it):
    its first actor creation builds Ray's serialisation context, and pyarrow stays out of the driver; exporting the
    actor class disassembles nothing (``aerodaas.clusters.ray_exports``) and the actor still answers."""
    import os
    import subprocess

    code = ("import dis, sys\n"
            "def no_disassembly(*a, **k):\n"
            "    raise AssertionError('the export disassembled the class')\n"
            "dis.dis = no_disassembly\n"
            "from aerodaas.runtime.ray_start import init_ray, shutdown_ray\n"
            "init_ray(None)\n"
            "import ray\n"
            "@ray.remote(num_cpus=0)\n"
            "class Echo:\n"
            "    def echo(self, x):\n"
            "        return x\n"
            "print(ray.get(Echo.remote().echo.remote(41)) + 1, 'pyarrow' in sys.modules, flush=True)\n"
            "shutdown_ray()\n")
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "AERODAAS_NO_ATTACH": "1", "RAY_TMPDIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300,
                         env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.split()[-2:] == ["42", "False"], out.stdout
