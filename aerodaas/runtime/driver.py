"""The runner: takes a loaded application (:class:`aerodaas.runtime.app_loader.Application`) or an environment's
robots and the run's options (:class:`aerodaas.runtime.options.RunOptions`), starts (or joins) Ray
(:mod:`aerodaas.runtime.ray_start`), turns the application's dataflow into the run's Ray actors
(:mod:`aerodaas.runtime.dataflow`: a drone actor per drone, an actor per deployed analytics replica, a dispatcher
per edge compute with scheduled analytics, a recorder per run), flies the mission
(:mod:`aerodaas.runtime.supervise`), finishes the recording and returns a :class:`MissionResult`.

Placement uses Ray node labels: an actor for compute on tier ``edge`` gets ``label_selector={"tier": "edge",
**compute labels}``, tier ``cloud`` ``{"tier": "cloud", ...}``. In local single-node mode (the default) Ray is
started here with the node labelled ``tier=edge``, cloud compute may use it (``in(edge,cloud)``) and compute labels
are not required. Ray's token authentication stays on (Ray >= 2.59 enables it for local clusters); the local
cluster listens on loopback only.
"""
from __future__ import annotations

import dataclasses
import os
import sys
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

from aerodaas.clusters.placement import gpu_placement_errors, placement_warning
from aerodaas.config import ConfigError
from aerodaas.config.robot import sensor_class
from aerodaas.plugins.registry import by_value_modules
from aerodaas.plugins.sensor import Delivery
from aerodaas.process.state import PROCESS
from aerodaas.protocol.specs import AnalyticsSchedulerSpec
from aerodaas.protocol.startup_probe import probe
from aerodaas.recording.health import FailureCount, assess, tally_failures
from aerodaas.runtime import ray_start
from aerodaas.runtime.app_loader import load_app
from aerodaas.runtime.dataflow import Placement, build_plan
from aerodaas.runtime.node_recorders import run_accounting
from aerodaas.runtime.options import RunOptions, actor_classes, check_actor_classes
from aerodaas.runtime.preflight import check_options, hitl_access, validate_graph
from aerodaas.runtime.supervise import error_cause as _cause
from aerodaas.runtime.supervise import collect_stats, start_actors, supervise
from aerodaas.runtime.teardown import close_actors
from aerodaas.schedulers.analytics_base import analytics_scheduler_class

if TYPE_CHECKING:
    from aerodaas.protocol.actor_classes import ActorClasses


@dataclass
class MissionResult:
    """Outcome of a mission: ``outcome`` (success / incomplete / timeout / interrupted / failed / refused: a vehicle
    refused our credentials, a MAVLink signing key it does not hold / recording_lost:
    the drones finished but the recorder actor died, see ``recording_losses`` / analytics_lost: under lock-step an
    analytics actor did not answer again within ``actor_restart_timeout_s``, see ``analytics_lost`` / degraded:
    the drones finished but a sensor or analytics failed more often than its limit, see ``degraded``), per-robot
    reports (visited waypoints, events, state history), per-actor stats, per-frame latency and the recording."""

    outcome: str
    robots: dict[str, dict]
    stats: dict[str, Any]
    latency: dict[str, Any]
    recording: str | None
    wall_s: float
    recording_counts: dict[str, int] = field(default_factory=dict)
    #: the recorder's failure (disk full, I/O error) or None: ``{error, last_recorded_ns, finished, ...}``; a run
    #: whose recording failed is not ``ok`` (exit code 1)
    recording_failure: dict[str, Any] | None = None
    recording_lost: int = 0
    recording_start_ns: int | None = None  # log time of sim time 0 (ns)
    #: one entry per death of the recorder actor (it was restarted into a new segment file):
    #: ``{segment, recorded_until_ns, next_segment, resumed_at_ns, previous_finished}``; a run with a loss is not
    #: ``ok`` (exit code 4)
    recording_losses: list[dict] = field(default_factory=list)
    #: the recording's segment files in order (one unless the recorder actor was restarted)
    recording_segments: list[str] = field(default_factory=list)
    #: message count of each segment before the last (None: unreadable); the last one's is ``recording_counts``
    recording_segment_messages: list[int | None] = field(default_factory=list)
    recording_duplicates: int = 0  # samples a restarted drone actor sent again, dropped (recorded once)
    #: ``recording.per_node``: each node recorder's file (its first segment); the run's whole recording is these and
    #: ``recording`` (``aerodaas merge`` joins them)
    recording_nodes: list[str] = field(default_factory=list)
    #: lock-step runs: the consumers (component ids) whose actor died and did not answer again within
    #: ``actor_restart_timeout_s``; their analytics were lost (outcome ``analytics_lost``, not ``ok``)
    analytics_lost: list[str] = field(default_factory=list)
    #: the recording's per-channel accounting, derived from the file(s) (:func:`aerodaas.recording.accounting.
    #: account_recording`: produced, recorded, lost per channel; ``lost_total``); None without one. A run whose
    #: recording lacks a numbered message is not ``ok`` (outcome ``recording_lost``, exit code 4)
    recording_accounting: dict[str, Any] | None = None
    #: the components whose failures exceeded their limit (:func:`aerodaas.recording.health.assess`: counted by
    #: the components and in the recording); a run with any is not ``ok`` (outcome ``degraded``, exit code 5)
    degraded: list[FailureCount] = field(default_factory=list)
    #: the servers this run exposed in clear text off loopback by choice (``--insecure``, ``hitl.insecure``): "the
    #: HITL API at http://..." ; the summary repeats them
    insecure: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return (self.outcome == "success" and self.recording_failure is None and not self.recording_losses
                and not self.analytics_lost and not self.recording_lost_messages and not self.degraded)

    @property
    def recording_lost_messages(self) -> int:
        """Messages numbered by their producers that are in no segment of the recording (0 without accounting)."""
        return int((self.recording_accounting or {}).get("lost_total", 0))


def allow_stop_interrupt(allowed: bool) -> None:
    """Whether a stop signal (:func:`request_stop`) may raise KeyboardInterrupt in the main thread from now on:
    True while the application is built, False around Ray's shutdown (the process's
    :class:`aerodaas.process.state.StopState`, which says why)."""
    PROCESS.stop.raise_ok = bool(allowed)


def request_stop(signum: int) -> None:
    """Called by the CLI's SIGINT/SIGTERM handler (main thread): record the stop and raise KeyboardInterrupt when
    that is safe now; otherwise the run stops at its next safe point
    (:meth:`aerodaas.process.state.StopState.request`)."""
    PROCESS.stop.request(signum)


def _start_scheduling(run: "_Run", placement: Any) -> list:
    """Start the cloud executors of the analytics scheduler (tier=cloud nodes, or this node without any) running
    copies of the scheduled analytics, and give every dispatcher actor of the plan (one per edge compute) the
    scheduler's spec. Returns the executors' handles (to kill at the end)."""
    cfg = run.env.cfg.analytics_scheduler
    policy_class = analytics_scheduler_class(cfg.name)  # the class travels, not its name
    analytics = {a.name: a for a in run.scheduled.values()}
    # cloud actors go to tier=cloud nodes, or to this node without any (placement: no compute labels here)
    executors = run.classes.start_cloud_executors(cfg.cloud_executors, mode="real",
                                                  selector=placement.selector("cloud", {}),
                                                  name_prefix="cloud-analytics", analytics=analytics,
                                                  ray_name_prefix=f"aerodaas/{run.plan.run_id}/cloud-analytics/")
    for a in run.plan.actors.values():
        if a.role == "dispatcher":
            a.spec.analytics_scheduler = AnalyticsSchedulerSpec(
                cfg.name, policy_class, cfg.resolved_workload(run.env.cfg), executors, list(cfg.network),
                cfg.jpeg_quality, 0)
    return executors


def _bind_handles(run: "_Run") -> dict:
    """The driver's handles per robot (drone, scheduler, cameras, analytics: the
    :class:`~aerodaas.protocol.handles.ComponentHandle` classes of ``run.classes`` into their actors), bound to the
    application's objects (``Robot.bind_drone``, live scheduler, pull getters)."""
    import ray  # lazy: heavy ray

    plan, actors, classes = run.plan, run.actors, run.classes
    loc = plan.location()
    handles: dict[str, dict] = {}
    for r in run.robots:
        ids = plan.robots[r.id]
        a_handles = {cid: classes.analytics_handle(actors[loc[cid]], cid) for cid in ids["analytics"]}
        home = actors[ids["actor"]]
        handles[r.id] = {"robot": r, "drone": classes.drone_handle(home, ids["drone"]),
                         "scheduler": classes.scheduler_handle(home, ids["scheduler"]), "analytics": a_handles,
                         "cameras": {sid: classes.camera_handle(home, cid) for sid, cid in ids["cameras"].items()},
                         "sched_obj": r.scheduler or run.env.trajectory_scheduler()}
        r.bind_drone(handles[r.id]["drone"])
        for s in r.sensors.values():
            s.get_data_stream().bind_runtime(_pull_getter(s, handles[r.id]))
        for a in run.graphs[r.id]:
            mine = [c for c in plan.analytics_instances[id(a)] if c in a_handles]
            if mine:
                h = a_handles[mine[0]]
                a.output.bind_runtime(lambda h=h: ray.get(h.get_latest.remote()))
    return handles


def run_application(app: Any, options: RunOptions | None = None) -> MissionResult:
    """Fly the mission of the loaded application ``app`` (:class:`aerodaas.runtime.app_loader.Application`) under
    ``options`` (default: :class:`RunOptions`); its classes travel to the actors by value. Checks the options
    against it first (bad input raises ConfigError / ValueError before Ray starts); once actors exist, every
    failure ends in a :class:`MissionResult` with the recording finished. Raises ValueError for an application
    without a mission, :class:`~aerodaas.runtime.ray_start.RayStartError` when Ray cannot be started or reached."""
    if app.mission is None or app.graph is None:
        raise ValueError(f"{app.path}: the application never called start_mission()")
    m = app.mission
    graph = (dict(app.graph.analytics), dict(app.graph.schedulers), dict(app.graph.scheduled))
    return _fly(m.env, list(m.robots), graph, options or RunOptions(), m.timeout, (app.module,))


def run_file(path: str, options: RunOptions | None = None,
             on_result: Callable[[MissionResult], None] | None = None) -> list[MissionResult]:
    """Load the app file ``path`` (:func:`aerodaas.runtime.app_loader.load_app`, with ``options.env_path``) and fly
    its missions in order, each with :func:`run_application`; code of the file after a mission runs once that
    mission flew, with its result (``aerodaas run`` does this). ``on_result`` is told each result. Returns the
    results (empty: the file never called ``start_mission()``). Raises what loading or a run raises; a stop signal
    (``aerodaas.process.state.PROCESS.stop``) after a mission ends the file there."""
    opts = options or RunOptions()
    results: list[MissionResult] = []
    app = load_app(path, opts.env_path)
    while app.mission is not None:
        results.append(run_application(app, opts))
        if on_result is not None:
            on_result(results[-1])
        if not app.continues or PROCESS.stop.stopped():
            break
        app = load_app(path, opts.env_path, flown=tuple(results))
    return results


def run_mission(env, robots: list, options: RunOptions | None = None, timeout: float | None = None) -> MissionResult:
    """Fly ``robots`` of ``env`` (what ``start_mission()`` does outside a loaded application) under ``options``
    (default: :class:`RunOptions`; its ``timeout`` wins over ``timeout``, wall seconds). Checks the application's
    graph and the options first: bad input raises before Ray starts; once actors exist, every failure ends in a
    :class:`MissionResult` (never a raw traceback) with the recording finished."""
    return _fly(env, robots, validate_graph(env, robots), options or RunOptions(), timeout, ())


def _fly(env, robots: list, graph: tuple, opts: RunOptions, timeout: float | None,
         by_value: tuple[str, ...]) -> MissionResult:
    """Check ``opts``, run the mission and return its result (``aerodaas run`` is told it by :func:`run_file`'s
    ``on_result``). The app's file (``by_value``'s modules, or ``__main__`` of ``python app.py``) is an input
    ``--record`` never overwrites."""
    check_actor_classes(opts)  # the entry point handed the actor classes (ValueError before Ray otherwise)
    files = (getattr(sys.modules.get(m), "__file__", None) for m in (*by_value, "__main__"))
    sim = check_options(env, robots, graph[1], opts, inputs=tuple(f for f in files if f))
    # the input passed its checks: now the actor modules (Ray, OpenCV) are imported, once, into the run's options
    opts = dataclasses.replace(opts, actors=actor_classes(opts))
    ray_start.start_ray_early(opts.address, opts.dashboard)  # in its own thread (see there), overlapping the plan
    PROCESS.stop.in_mission = True
    try:
        return _run_mission(_Run(env, robots, *graph, sim, opts,
                                 opts.timeout if opts.timeout is not None else timeout, by_value))
    finally:
        PROCESS.stop.in_mission = False


@dataclass
class _Run:
    """One run in progress: the application's part (env, robots, graph), the options and what Ray gave it."""

    env: Any
    robots: list
    graphs: dict
    scheds: dict
    scheduled: dict
    sim: Any
    opts: RunOptions
    timeout: float | None
    by_value: tuple[str, ...]
    t_start: float = field(default_factory=time.monotonic)
    epoch_ns: int = 0
    plan: Any = None
    has_cloud: bool = False
    actors: dict = field(default_factory=dict)
    cloud_executors: list = field(default_factory=list)
    handles: dict = field(default_factory=dict)
    reports: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    latency: dict = field(default_factory=dict)
    failure: str | None = None
    robot_errors: dict = field(default_factory=dict)  # robot id -> its own error when the run could not start
    robot_refused: set = field(default_factory=set)  # robots whose vehicle refused our credentials (outcome refused)
    insecure: list = field(default_factory=list)  # servers of the run in clear text off loopback (--insecure)
    recorder_described: dict = field(default_factory=dict)  # the recorder actor's set-up answer (its live view URL)

    @property
    def classes(self) -> ActorClasses:
        """The run's actor and handle classes (``opts.actors``, handed by the entry point)."""
        return actor_classes(self.opts)


def _plan_run(run: _Run) -> Any:
    """Start (or join) Ray, let the application's classes travel by value, plan the actors and say where they
    go. Returns the cluster's :class:`~aerodaas.runtime.dataflow.Placement`."""
    import ray  # lazy: heavy ray

    opts = run.opts
    probe("app_built")
    if PROCESS.stop.stopped():  # stopped while the app was built: nothing started, nothing to record
        raise KeyboardInterrupt(f"signal {PROCESS.stop.signals[0]}")
    allow_stop_interrupt(False)  # from here on a stop signal is taken at the safe points (see request_stop)
    run.has_cloud = ray_start.ensure_ray(opts.address, opts.dashboard)
    probe("ray_ready")
    run.epoch_ns = time.time_ns()
    for mod in [*by_value_modules(), *run.by_value]:  # plug-ins outside any installed package, the app itself
        if mod in sys.modules:
            ray.cloudpickle.register_pickle_by_value(sys.modules[mod])
    run.plan = build_plan(run.env, run.robots, run.graphs, run.scheds, run.sim, record=opts.record, live=opts.live,
                          live_access=opts.live_access,
                          scheduled=run.scheduled, epoch_ns=run.epoch_ns,
                          run_id=opts.run_id or os.environ.get("AERODAAS_RUN_ID") or None)
    placement = Placement(has_cloud=run.has_cloud, local=ray_start.started_here() and not opts.address)
    _check_gpus(run.plan, placement)
    if not placement.local:
        warning = placement_warning(run.plan)
        if warning:
            print(f"aerodaas: warning: {warning}", file=sys.stderr, flush=True)
    if opts.progress:
        kinds: dict[str, int] = {}
        for a in run.plan.actors.values():
            kinds[a.role] = kinds.get(a.role, 0) + 1
        # `ray list actors` talks to the dashboard's state API, so the hint names the dashboard, not the GCS
        dashboard_url = ray._private.worker.get_dashboard_url() if (opts.dashboard or opts.address) else ""
        print(f"aerodaas: run {run.plan.run_id}: " + ", ".join(f"{n} {k}" for k, n in kinds.items()) + " actor(s) on "
              f"Ray {ray.get_runtime_context().gcs_address}" + (f" (see them: RAY_AUTH_MODE=token ray list actors "
              f"--address http://{dashboard_url})" if dashboard_url else
              " (run with --dashboard to see them with `ray list actors`)"), flush=True)
    return placement


def _check_gpus(plan: Any, placement: Any) -> None:
    """Every actor asking for GPUs has a live node of its compute with them (else Ray would hold it pending for
    ever and the run would wait). Raises ConfigError naming each actor, its selector and the nodes' GPUs."""
    import ray  # lazy: heavy ray

    if not any(a.num_gpus for a in plan.actors.values()):
        return
    errors = gpu_placement_errors(plan, placement, ray.nodes())
    if errors:
        raise ConfigError("; ".join(errors))


def _start_actors(run: _Run, placement: Any) -> list:
    """Start every actor of the plan and set them up at once (drones connect to their vehicles); the recorder's
    answer is read first (kept in ``run.recorder_described``: its live view's URL): a bad file or live view is the
    error reported. Returns each other actor's description; raises the first error (``run.robot_errors`` holds each
    robot's own)."""
    import ray  # lazy: heavy ray

    if run.scheduled:
        run.cloud_executors = _start_scheduling(run, placement)
    run.actors = start_actors(run.plan, placement, run.env.cfg.actor_max_restarts, run.classes)
    probe("actors_created")
    rec_setup = run.actors["recorder"].setup.remote()
    others = [h.setup.remote() for hid, h in run.actors.items() if hid != "recorder"]
    run.recorder_described = ray.get(rec_setup) or {}
    described, first = [], None
    for ref in others:  # every actor's answer: each robot that could not connect gets its own error
        try:
            described.append(ray.get(ref))
        except Exception as e:  # noqa: BLE001
            per = getattr(getattr(e, "cause", None), "errors", None) or getattr(e, "errors", None)
            if isinstance(per, dict):
                run.robot_errors.update(per)
                run.robot_refused.update(getattr(getattr(e, "cause", None), "refused", None)
                                         or getattr(e, "refused", None) or ())
            first = first or e
    if first is not None:
        raise first
    return described


def _start_hitl(run: _Run):
    """The human-in-the-loop API of the run when it is on (``--hitl`` or ``hitl.enabled``), started; else None.
    The token is not printed: the console says where the owner-only state file is (``aerodaas inject`` reads it)."""
    hcfg, opts = run.env.cfg.hitl, run.opts
    if not (opts.hitl if opts.hitl is not None else hcfg.enabled):
        return None
    # only now: the HITL server imports FastAPI (a quarter of a second of CPU between the actors' set-up and the
    # mission's start, paid by every run when it sat above the check)
    from aerodaas.tools.hitl import HitlServer  # lazy: heavy fastapi
    from aerodaas.tools.hitl_client import state_file  # lazy: only a run with the HITL API writes its state file

    access = hitl_access(run.env, opts)
    hitl = HitlServer({rid: {"drone": h["drone"], "scheduler": h["scheduler"]} for rid, h in run.handles.items()},
                      host=hcfg.host, port=opts.hitl_port if opts.hitl_port is not None else hcfg.port,
                      token=hcfg.token, docs=hcfg.docs, cert_file=access.cert_file, key_file=access.key_file,
                      insecure=access.insecure).start()
    run.env.hitl = hitl
    source = "generated" if hitl.generated_token else "from environment.json"
    print(f"aerodaas: human-in-the-loop API at {hitl.url}  (bearer token {source}: in {state_file()}, owner only)",
          flush=True)
    if hitl.insecure:  # what the server itself does, repeated in the summary
        run.insecure.append(f"the HITL API at {hitl.url}")
        print(f"aerodaas: WARNING: the HITL API serves plain HTTP off loopback ({hitl.url}, insecure): its token "
              f"and requests can be read on the network", file=sys.stderr, flush=True)
    return hitl


def _supervise(run: _Run, described: list) -> None:
    """Bind the application's objects to the actors, run the start hooks, fly until the mission ends and collect
    the stats."""
    for r in run.robots:
        h = run.handles[r.id]
        if run.scheds[r.id] is h["sched_obj"]:  # not shared: live add/clear go to this robot's queue
            h["sched_obj"].bind_remote(h["scheduler"])
    for h in run.handles.values():
        h["robot"].run_start_hooks()
    allow_stop_interrupt(True)
    t_fly = time.monotonic()
    run.reports = supervise(run.plan, run.actors, run.handles, run.timeout, run.opts.progress,
                            PROCESS.stop.stopped, restart_wait_s=run.env.cfg.actor_restart_timeout_s)
    fly_s = time.monotonic() - t_fly
    allow_stop_interrupt(False)
    run.stats, run.latency = collect_stats(run.handles, run.actors, run.plan)
    if not run.stats["_settle"]["idle"]:
        print(f"aerodaas: warning: messages were still in flight between actors after "
              f"{run.stats['_settle']['s']:.0f} s; the counts below may leave them out", file=sys.stderr, flush=True)
    # the flying part alone (actors started and wired, until the mission ended), s: what benchmarks measure
    run.stats["_timing"] = {"mission_s": round(fly_s, 3), "startup_s": round(t_fly - run.t_start, 3)}
    run.stats["_plan"] = {"run": run.plan.run_id, "actors": {hid: a.name for hid, a in run.plan.actors.items()},
                          "placed": {d.get("host"): d.get("node_id") for d in described}}


def _release(run: _Run, hitl: Any) -> tuple[dict, dict]:
    """Stop the HITL API, close every actor (the recording finished), unbind the application's objects and kill
    the actors. Returns (recorded message counts, recording report)."""
    import ray  # lazy: heavy ray

    allow_stop_interrupt(False)
    if hitl is not None:
        hitl.stop()
        run.env.hitl = None
    counts, rec_report = close_actors(run.actors, run.opts.record)
    for h in run.handles.values():
        h["robot"].bind_drone(None)
        h["sched_obj"].bind_remote(None)
        for s in h["robot"].sensors.values():
            s.get_data_stream().bind_runtime(None)
    for h in [*run.actors.values(), *run.cloud_executors]:
        try:
            ray.kill(h, no_restart=True)
        except Exception:  # noqa: BLE001 - an actor on a lost node is already gone
            pass
    return counts, rec_report


def _announce_live(run: _Run, url: str) -> None:
    """Print where the live view is; with a token, write it to the owner-only state file ``live.json``
    (:func:`aerodaas.liveview.server.write_live_state`) and print that file's path, never the token."""
    from aerodaas.liveview.server import write_live_state  # lazy: heavy cv2, mcap, protobuf

    access = run.opts.live_access
    where = ""
    if access is not None and access.token:
        where = f"; token in {write_live_state(url, access)}, owner only: add /?token=... to the URL"
    print(f"aerodaas: live view at {url} (Foxglove: Open connection -> Foxglove WebSocket{where})", flush=True)
    if access is not None and access.insecure:
        run.insecure.append(f"the live view at {url}")
        print(f"aerodaas: WARNING: the live view serves plain WebSocket off loopback ({url}, --insecure): the run "
              f"can be read on the network", file=sys.stderr, flush=True)


def _run_mission(run: _Run) -> MissionResult:
    """Plan, start, fly and tear down ``run``; every failure once Ray runs ends in the result."""
    import ray  # lazy: heavy ray

    placement = _plan_run(run)
    hitl = None
    counts: dict[str, int] = {}
    rec_report: dict[str, Any] = {}
    try:
        try:
            described = _start_actors(run, placement)
        except KeyboardInterrupt:
            raise
        except Exception as e:  # noqa: BLE001 - e.g. a vehicle that does not answer: a failed run, not a traceback
            run.failure = _cause(e)
            for rid, err in run.robot_errors.items():
                print(f"aerodaas: robot {rid!r} could not start: {err}", file=sys.stderr, flush=True)
            print(f"aerodaas: the run could not start: {run.failure}", file=sys.stderr, flush=True)
            described = []
        if run.failure is None:  # the recorder's set-up answer, read once (no second round trip to it)
            live_url = run.recorder_described.get("live_url")
            if live_url:
                _announce_live(run, live_url)
        probe("hosts_ready")
        if run.failure is None:
            run.handles = _bind_handles(run)
            hitl = _start_hitl(run)
            _supervise(run, described)
    finally:
        counts, rec_report = _release(run, hitl)
    allow_stop_interrupt(True)  # back in the application
    return _result(run, counts, rec_report)


def _recording_accounting(record: str | None, rec_report: dict) -> dict[str, Any] | None:
    """The recording's accounting read back from its file(s) (``rec_report["segments"]``, else ``record``),
    None without a recording or when it cannot be read (the summary then says what the recorder reported)."""
    paths = rec_report.get("segments") or ([record] if record else [])
    nodes = [r.get("segments") or [] for r in (rec_report.get("nodes") or {}).values()]  # recording.per_node
    if not paths or not all(os.path.isfile(p) for p in [*paths, *(p for n in nodes for p in n)]):
        return None

    try:
        return run_accounting(paths, nodes)
    except (OSError, ValueError) as e:
        print(f"aerodaas: warning: the recording's accounting could not be read: {type(e).__name__}: {e}",
              file=sys.stderr)
        return None


def _result(run: _Run, counts: dict, rec_report: dict) -> MissionResult:
    """The run's :class:`MissionResult` (a robot without a report failed; a lost recording segment or analytics
    is not a success); the application's end hooks are told it."""
    for r in run.robots:
        err = run.robot_errors.get(r.id) or (f"not started: another robot could not connect ({run.failure})"
                                             if run.robot_errors else run.failure) or \
            "no report (the run did not start)"
        run.reports.setdefault(r.id, {"robot": r.id, "error": err,
                                      "outcome": "refused" if r.id in run.robot_refused else "failed"})
    outcomes = [rep.get("outcome") or "failed" for rep in run.reports.values()]
    outcome = "success" if outcomes and all(o == "success" for o in outcomes) else next(
        (o for o in outcomes if o != "success"), "failed")
    accounting = _recording_accounting(run.opts.record, rec_report)
    stats = run.stats
    lost_analytics = sorted({cid for h in (stats.get("_hosts") or {}).values() if isinstance(h, dict)
                             for cid in h.get("lost_consumers", [])}) if isinstance(stats, dict) else []
    if outcome == "success" and lost_analytics:
        outcome = "analytics_lost"  # the drones finished, flying on without an analytics that never came back
    if outcome == "success" and (rec_report.get("losses") or (accounting or {}).get("lost_total")):
        outcome = "recording_lost"  # the drones finished, but the run's truth has a hole: not a success
    degraded = component_failures(run.reports, stats, rec_report.get("segments") or (
        [run.opts.record] if run.opts.record and os.path.isfile(run.opts.record) else []))
    if outcome == "success" and degraded:
        outcome = "degraded"  # the drones finished, but a sensor or an analytics failed more than its limit
    result = MissionResult(outcome=outcome, robots=run.reports, stats=stats, latency=run.latency,
                           recording=run.opts.record, wall_s=time.monotonic() - run.t_start, recording_counts=counts,
                           recording_failure=rec_report.get("failure"), recording_lost=rec_report.get("lost", 0),
                           recording_start_ns=run.epoch_ns, recording_losses=rec_report.get("losses") or [],
                           recording_segments=rec_report.get("segments") or [],
                           recording_segment_messages=rec_report.get("segment_messages") or [],
                           recording_duplicates=rec_report.get("duplicates", 0), analytics_lost=lost_analytics,
                           recording_nodes=[(r.get("segments") or [None])[0] or h
                                            for h, r in (rec_report.get("nodes") or {}).items()],
                           recording_accounting=accounting, degraded=degraded, insecure=list(run.insecure))
    for h in run.handles.values():
        h["robot"].run_end_hooks(result)
    return result


def component_failures(reports: dict, stats: Any, paths: list[str]) -> list[FailureCount]:
    """The sensors and analytics over their failure limit (:func:`aerodaas.recording.health.assess`), from their
    own counts (the drones' ``reports`` for plug-in sensors, the actors' ``stats`` for analytics: one entry per
    analytics component) and the failures recorded in ``paths`` (the recording's segments; none: own counts
    only)."""
    own: list[FailureCount] = []
    for rep in reports.values():
        for ps in (rep.get("plugin_sensors") or {}).values():
            if isinstance(ps, dict) and ps.get("health"):
                own.append(FailureCount.from_dict(ps["health"]))
    seen: set[str] = set()
    for rid, st in (stats.items() if isinstance(stats, dict) else ()):
        for a in (st.get("analytics") or []) if isinstance(st, dict) and not rid.startswith("_") else []:
            h = a.get("health") if isinstance(a, dict) else None
            if h and h.get("cid") not in seen:  # an analytics serving several robots is listed under each
                seen.add(h.get("cid"))
                own.append(FailureCount.from_dict(h))
    return assess(own, tally_failures(paths) if paths else None)


def _pull_getter(sensor, h: dict):
    import ray  # lazy: heavy ray

    cls = sensor_class(sensor.type)

    def get():
        if cls.delivery.frames and sensor.id in h["cameras"]:
            return ray.get(h["cameras"][sensor.id].get_latest.remote())
        st = ray.get(h["drone"].status.remote())
        return st if cls.delivery is Delivery.MISSION_STATUS else ray.get(h["drone"].report.remote()).get("position")

    return get
