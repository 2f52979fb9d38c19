"""Shared fixtures: one local Ray session for every test that needs it, and the shared data location."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA_DIR = Path(os.environ.get("AERODAAS_DATA_DIR", REPO.parent / "shared" / "data")).resolve()
MODEL_DIR = Path(os.environ.get("AERODAAS_MODEL_DIR", DATA_DIR / "models")).resolve()

# a test's `aerodaas run` starts a Ray of its own: never attach to a cluster of `aerodaas up` that the developer left
# running (its workers would run that cluster's installed code, not this checkout's); the tests of `up` itself and
# `bench startup --mode attached` use a private AERODAAS_STATE_DIR and clear this
os.environ.setdefault("AERODAAS_NO_ATTACH", "1")



def skip_or_fail(reason: str) -> None:
    """A test that cannot run here (no shared data, no test rig, no network namespace): skipped on a developer's
    machine, failed when the environment variable ``CI`` is set (CI provides all of it, so a missing piece there is
    a broken CI machine, not a reason to pass). Raises pytest's Skipped or Failed exception, naming ``reason``."""
    if os.environ.get("CI"):
        pytest.fail(f"{reason} (CI is set: a test that cannot run fails)", pytrace=False)
    pytest.skip(reason)


#: why the tests of :data:`needs_data` cannot run here, or None
DATA_MISSING = (None if (DATA_DIR / "imagery").is_dir() and (MODEL_DIR / "yolox_nano.onnx").is_file() else
                f"shared data not found at {DATA_DIR} (set AERODAAS_DATA_DIR / AERODAAS_MODEL_DIR)")


@pytest.fixture(scope="session")
def _shared_data() -> None:
    """The shared imagery and the detector model are there (:data:`needs_data`), or :func:`skip_or_fail`. Session
    scoped, so that it is checked before any module fixture that reads the data."""
    if DATA_MISSING is not None:
        skip_or_fail(DATA_MISSING)


#: a test (or, as ``pytestmark``, a module) that reads the shared imagery or the detector model: skipped without
#: them, failed in CI (:func:`skip_or_fail`)
needs_data = pytest.mark.usefixtures("_shared_data")


def needs_path(*paths: Path, reason: str):
    """The mark of a test (a module's ``pytestmark``, a case's ``pytest.param(..., marks=...)``) that reads
    ``paths`` (shared data: files or folders): :func:`skip_or_fail` with ``reason`` when one is missing, checked
    when the test is set up (:func:`pytest_runtest_setup`)."""
    return pytest.mark.needs_path(*paths, reason=reason)


#: :data:`needs_data` for one case of a parametrized test (``pytest.param(..., marks=needs_data_case)``, which cannot
#: take a fixture)
needs_data_case = needs_path(DATA_DIR / "imagery", MODEL_DIR / "yolox_nano.onnx", reason=str(DATA_MISSING))


def pytest_runtest_setup(item):
    """A test marked :func:`needs_path` whose files are not all there: :func:`skip_or_fail`."""
    for mark in item.iter_markers("needs_path"):
        missing = [str(p) for p in mark.args if not Path(p).exists()]
        if missing:
            skip_or_fail(f"{mark.kwargs.get('reason', 'shared data missing')}: {', '.join(missing)} not found")


@pytest.fixture(scope="session")
def _sitl_rig() -> None:
    """The real firmware and a private network namespace are there (:func:`tests.firmware.sitl.namespace_skip_reason`), or
    :func:`skip_or_fail`: checked once per session, before the module fixtures that start the firmware."""
    from tests.firmware import sitl

    reason = sitl.namespace_skip_reason()
    if reason is not None:
        skip_or_fail(reason)


#: a test (or, as ``pytestmark``, a module) flying real SITL firmware in a private network namespace: skipped
#: without them, failed in CI (:func:`skip_or_fail`)
needs_sitl = pytest.mark.usefixtures("_sitl_rig")


#: the inference workload (the Ocularone trace) that the scheduler tests and benchmarks replay
WORKLOAD_JSON = DATA_DIR / "workloads" / "ocularone_lambda.json"


@pytest.fixture(scope="session")
def _workload() -> None:
    """The workload file :data:`WORKLOAD_JSON` is there, or :func:`skip_or_fail`."""
    if not WORKLOAD_JSON.is_file():
        skip_or_fail(f"no workload at {WORKLOAD_JSON} (set AERODAAS_DATA_DIR)")


#: a test (or, as ``pytestmark``, a module) that replays the workload: skipped without it, failed in CI
needs_workload = pytest.mark.usefixtures("_workload")


#: the groups that the development tier leaves out: real firmware, `ray up`, multi-node clusters, fault runs,
#: missions flown on a real-time video stream and a real Label Studio server
SLOW_GROUPS = ("sitl", "rayup", "cluster", "faults", "video", "realtime", "labelstudio")


#: the development tier's longest files, longest first (worker-seconds each, 3 workers on this shared 2-core machine,
#: 2026-11-26, load 6-36, mean 15.6: 262 s for the first down to 36 s for the last; 3,439 s in all, 1,224 s wall;
#: test_layers.py's 131 s were before its fresh-import check stopped recompiling). ``--dist loadgroup`` hands whole
#: files to the workers in the collection's order, so these start first and the many short files fill in at the end:
#: a longest-first schedule (files of 111 s and 91 s under tests/schedulers/, not listed before, were collected
#: near the end). Only the order: a file missing here runs after them, a stale entry costs time, never a result
LONGEST_FIRST = ("test_e2e.py", "test_bench_cli.py", "test_missions.py", "test_example_plugins.py",
                 "test_backends_e2e.py", "test_layers.py", "test_non_anticipation.py", "test_live_and_foxglove.py",
                 "test_mavlink_failsafe.py", "test_liveview_npm_client.py", "test_burst_arrivals.py",
                 "test_dataplane.py", "test_record_no_clobber.py", "test_video_source.py",
                 "test_perception_track_recording.py", "test_no_secret_in_outputs.py", "test_component_health.py",
                 "test_analytics_contract.py", "test_phase_deadlines.py", "test_analytics_scheduling.py",
                 "test_mavlink.py", "test_bench_json_stdout.py", "test_mavlink_end.py", "test_plugin_registry.py",
                 "test_tls_access.py", "test_gimbal_missions.py", "test_mavlink_signing.py", "test_app_value.py",
                 "test_mavlink_fleet.py", "test_app_errors_before_ray.py", "test_user_scheduler_plugin.py",
                 "test_perception_providers.py", "test_trajectory_scheduler_in_environment.py")


#: the slow tier's other lane, longest first (seconds, serial, 2026-11-26 at load 2-9: test_faults 735, test_ray_up
#: 280, test_example_plugins 152, test_runtime_actors 146, test_edgecloud_cluster 123, test_bad_input 92,
#: test_bench_json_stdout 80); after :data:`LONGEST_FIRST` in the rank, which only the development tier's files use
SLOW_LONGEST_FIRST = ("test_faults.py", "test_ray_up.py", "test_example_plugins.py", "test_runtime_actors.py",
                      "test_edgecloud_cluster.py", "test_bad_input.py", "test_bench_json_stdout.py",
                      "test_liveview_npm_client.py", "test_json_inputs.py", "test_perception_providers.py",
                      "test_train_detector.py", "test_safety_limits.py")


def pytest_configure(config):
    """Under pytest-xdist, keep the collection's order of files (see :data:`LONGEST_FIRST`): xdist otherwise sorts
    them by their number of tests, which puts the files of a few long end-to-end runs last."""
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


@pytest.hookimpl(wrapper=True)
def pytest_collection(session):
    """Collect with ``sys.dont_write_bytecode`` off in this pytest process, so that pytest keeps the test modules
    whose asserts it rewrote (``__pycache__/*-pytest-*.pyc``, read back by every later collection) even where
    ``PYTHONDONTWRITEBYTECODE`` is set, as on CI machines: each pytest process (each xdist worker) otherwise rewrites
    all of them again, about half of its collection's CPU (docs/results/test-tiers.md). The flag is restored after
    the collection; subprocesses keep the environment's."""
    saved = sys.dont_write_bytecode
    sys.dont_write_bytecode = False
    try:
        return (yield)
    finally:
        sys.dont_write_bytecode = saved


#: the slow groups whose outcome needs the CPU when the vehicle's or the stream's clock says so (real firmware, a
#: real-time video sender, a wall-clock runtime): in the slow tier they share one lane, one test at a time
REALTIME_GROUPS = ("sitl", "video", "realtime")
#: the name of that lane (an ``xdist_group``); every other slow file is a lane unit of its own, but for the next
REALTIME_LANE = "realtime-lane"
#: the tests that start Ray clusters of several nodes or `aerodaas up`'s persistent cluster share one lane too: they
#: bind Ray's fixed default ports on loopback (the dashboard's 8265: `aerodaas up` failed with "already occupied"
#: beside a LocalCluster with a dashboard, 2026-11-26), so two of them never run at once
CLUSTER_LANE = "cluster-lane"
CLUSTER_GROUPS = ("cluster", "rayup")
CLUSTER_FILES = ("test_persistent_cluster.py", "test_example_plugins.py", "test_warm_pool.py")


def slow_lane(item) -> str:
    """The ``xdist_group`` of a slow test under ``--dist loadgroup`` (CI: both tiers on 3 workers): every real-time test
    (:data:`REALTIME_GROUPS`) in :data:`REALTIME_LANE`, so one worker runs them one after the other, never two at
    once; any other test with the rest of its file (its module fixtures start once: a Ray cluster, a firmware
    boot), the files handed to the other workers as they free up; multi-node and persistent clusters in
    :data:`CLUSTER_LANE`, one at a time. The real-time lane comes first in the collection,
    so xdist starts it at once and it ends about when the other workers' files do."""
    if any(item.get_closest_marker(g) for g in REALTIME_GROUPS):
        return REALTIME_LANE
    if any(item.get_closest_marker(g) for g in CLUSTER_GROUPS) or item.path.name in CLUSTER_FILES:
        return CLUSTER_LANE
    return item.path.name


#: the order of the files on an xdist worker (--dist loadgroup and loadfile hand units out in the collection's
#: order): the fault scenarios and the cluster lane (its first file is ``test_example_plugins.py``) first among the
#: slow files, the development tier's longest files, then the rest of the slow files; a name missing here runs
#: after them all. CI runs both tiers in one run (every test has a lane; docs/architecture.md, Development loop)
RANK = (SLOW_LONGEST_FIRST[:1] + ("test_example_plugins.py",) + LONGEST_FIRST
        + tuple(n for n in SLOW_LONGEST_FIRST[1:] if n not in LONGEST_FIRST))


#: the development tier's files that mostly wait on a clock and start no Ray of their own: an emulated autopilot or
#: Tello flown at its speed-up in the test's process, real-time video senders, a live-view client that stops reading.
#: They use about a tenth of a core while they run (docs/results/test-tiers.md), so under ``pytest -n 4 --dist
#: loadgroup`` they share one lane (:data:`WAITING_LANE`) on a fourth worker beside three that run the CPU-bound rest:
#: the cores idle while a test waits are filled, and no more than three workers start actors and Ray sessions at
#: once. A file listed here that has become CPU-bound only costs time
WAITING_FILES = ("test_mavlink.py", "test_video_source.py", "test_tello.py", "test_mavlink_links.py",
                 "test_mission_plan_ids.py", "test_signing_clis.py", "test_mavlink_speed_margin.py",
                 "test_hitl_token_scope.py", "test_mavlink_fence.py", "test_mission_cli.py", "test_live_slow_client.py",
                 "test_cloud_pool_losses.py", "test_channel.py")
#: the name of that lane (an ``xdist_group``)
WAITING_LANE = "waiting-lane"
#: the development tier's architecture checks (``tests/architecture``) but its fresh-interpreter import budgets: they
#: walk the syntax trees of the same few hundred files, parsed once per pytest process and kept while they run one
#: after the other (``tests/architecture/conftest.py``), so under ``--dist loadgroup`` they share one lane: one
#: worker parses the code base once instead of each file's worker once more
ARCHITECTURE_LANE = "architecture-lane"
ARCHITECTURE_OWN_UNITS = ("test_lazy_imports.py",)
#: the lanes that come first in the collection, so that xdist hands each to a worker of its own at once
FIRST_LANES = (REALTIME_LANE, WAITING_LANE)


def lane(item) -> str:
    """The ``xdist_group`` of any test: a slow test's :func:`slow_lane`; a development-tier test's file name,
    :data:`WAITING_LANE` for the files of :data:`WAITING_FILES`, or :data:`ARCHITECTURE_LANE`. Under ``--dist
    loadgroup`` (both tiers, as the README runs them) a file stays on one worker with its module fixtures; under
    ``--dist loadfile`` the marks change nothing."""
    if item.get_closest_marker("slow"):
        return slow_lane(item)
    if item.path.parent.name == "architecture" and item.path.name not in ARCHITECTURE_OWN_UNITS:
        return ARCHITECTURE_LANE
    return WAITING_LANE if item.path.name in WAITING_FILES else item.path.name


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own hook, which reads the xdist_group marks set here
def pytest_collection_modifyitems(config, items):
    """Mark every test of a slow group ``slow`` too, so that ``pytest -m "not slow"`` is the development tier
    (everything but SITL, ``ray up``, cluster, fault, video and real-time runs); CI runs everything. Every test gets
    its lane (:func:`lane`, read by ``--dist loadgroup``). On an xdist worker, the real-time and waiting lanes come
    first, then the files in :data:`RANK`'s order (the tests of a file keep theirs)."""
    for item in items:
        if any(item.get_closest_marker(g) for g in SLOW_GROUPS):
            item.add_marker(pytest.mark.slow)
        item.add_marker(pytest.mark.xdist_group(lane(item)))
    if os.environ.get("PYTEST_XDIST_WORKER"):
        rank: dict[str, int] = {}
        for i, name in enumerate(RANK):  # a name listed twice keeps its first place
            rank.setdefault(name, i)
        def first_lane(item) -> bool:
            return any(m.args and m.args[0] in FIRST_LANES for m in item.iter_markers("xdist_group"))

        items.sort(key=lambda item: (not first_lane(item), rank.get(item.path.name, len(rank))))


@pytest.fixture(scope="session")
def ray_session():
    """A local Ray with this node labelled tier=edge (token auth on, loopback only), shared by all e2e tests of this
    pytest worker; yields which session it is (:func:`tests.runtime.shared_ray.session_id`)."""
    from aerodaas.runtime import ray_start

    from tests.runtime.shared_ray import session_id

    ray_start.ensure_ray(None)
    yield session_id()
    ray_start.shutdown_ray()


#: the test modules whose first test on this worker found the shared Ray session clean (:func:`_shared_ray_stays_clean`)
_RAY_MODULES_CHECKED: set[str] = set()


@pytest.fixture(autouse=True)
def _shared_ray_stays_clean(request):
    """Around each test that uses the shared ``ray_session`` (directly or through a fixture): before the first test
    of a module, the session holds no run actor or placement group (what an earlier module and its fixtures left:
    :func:`tests.runtime.shared_ray.wait_clean`); after each test, none that appeared during the test (a module
    fixture's, there before, is checked at the next module) and the session is still the same one (nobody shut it
    down or started another). Else the test errors, naming what was left."""
    if "ray_session" not in request.fixturenames:
        yield
        return
    from tests.runtime.shared_ray import leftovers, session_id, wait_clean

    session = request.getfixturevalue("ray_session")
    module = request.node.module.__name__
    if module not in _RAY_MODULES_CHECKED:
        _RAY_MODULES_CHECKED.add(module)
        left = wait_clean()
        assert not left, f"the shared Ray session holds what earlier tests left, before {module}: {left}"
    before = leftovers()  # the module fixtures' actors
    yield
    now = session_id()
    assert now == session, f"the shared Ray session changed during the test: {session} -> {now}"
    left = wait_clean(before)
    assert not left, f"the test left these in the shared Ray session: {left}"


@pytest.fixture
def run_options():
    """The test's own run options (no progress lines, the built-in actor classes), passed explicitly to what runs
    the mission (``start_mission(options=...)``, :func:`aerodaas.runtime.driver.run_file`)."""
    from aerodaas.actors.builtin.catalogue import BUILTIN_ACTORS
    from aerodaas.runtime.options import RunOptions

    return RunOptions(progress=False, actors=BUILTIN_ACTORS)


@pytest.fixture
def data_env(monkeypatch):
    monkeypatch.setenv("AERODAAS_DATA_DIR", str(DATA_DIR))
    monkeypatch.setenv("AERODAAS_MODEL_DIR", str(MODEL_DIR))
