"""Runtime glue: checks an application, starts (or joins) Ray, turns the application's dataflow into the run's
Ray actors (:mod:`aerodaas.runtime.dataflow`: a drone actor per drone, an actor per deployed analytics replica, a
dispatcher per edge compute with scheduled analytics, a recorder per run), flies the mission
(:mod:`aerodaas.runtime.supervise`), finishes the recording and returns a :class:`MissionResult`.

Placement uses Ray node labels: an actor for compute on tier ``edge`` gets ``label_selector={"tier": "edge",
**compute labels}``, tier ``cloud`` ``{"tier": "cloud", ...}``. In local single-node mode (the default) Ray is
started here with the node labelled ``tier=edge``, cloud compute may use it (``in(edge,cloud)``) and compute labels
are not required. Ray's token authentication stays on (Ray >= 2.59 enables it for local clusters); the local
cluster listens on loopback only.
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any


from aerodaas.config import SimulationConfig
from aerodaas.runtime.preflight import check_clocks, robot_schedulers as _robot_schedulers, validate  # noqa: F401 - tests use it
from aerodaas.clusters.loopback import loopback_only
from aerodaas.runtime.report import format_summary  # noqa: F401 - ``runtime.format_summary`` is what ``aerodaas run`` prints
from aerodaas.runtime.supervise import error_cause as _cause


@dataclass
class RunOptions:
    """Options the CLI (or a test) sets before running an application."""

    record: str | None = None
    speedup: float | None = None
    lockstep: bool | None = None
    timeout: float | None = None
    address: str | None = None
    env_path: str | None = None
    progress: bool = True
    hitl: bool | None = None  # force the human-in-the-loop API on/off (default: environment.json hitl.enabled)
    hitl_port: int | None = None
    live: str | None = None  # serve the run to Foxglove over WebSocket on this HOST:PORT (aerodaas.liveview.server)
    #: a local Ray also starts its dashboard on 127.0.0.1 (``aerodaas run --dashboard``: it serves
    #: ``ray list actors`` and the actors view; off by default: it adds seconds to the start and on a loaded machine
    #: can fail to start, which then costs a retry without it)
    dashboard: bool = False
    #: the run's id in its actors' names (``aerodaas/<run id>/...``); None: a random one per run
    run_id: str | None = None
    #: ``aerodaas plan``: build and check everything, then raise :class:`PlanReady` instead of starting Ray
    plan_only: bool = False
    #: start Ray in the background as soon as the application's Environment is validated (``aerodaas run``): an
    #: invalid environment then fails before any Ray process exists, and a valid one overlaps Ray's start with
    #: building the rest of the application
    early_ray: bool = False
    #: --overwrite: --record may replace an existing file that is not an AeroDaaS recording
    overwrite: bool = False


OPTIONS = RunOptions()


@dataclass
class MissionResult:
    """Outcome of a mission: ``outcome`` (success / incomplete / timeout / interrupted / failed / recording_lost:
    the drones finished but the recorder actor died, see ``recording_losses`` / analytics_lost: under lock-step an
    analytics actor did not answer again within ``actor_restart_timeout_s``, see ``analytics_lost``), per-robot
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
    #: lock-step runs: the consumers (component ids) whose actor died and did not answer again within
    #: ``actor_restart_timeout_s``; their analytics were lost (outcome ``analytics_lost``, not ``ok``)
    analytics_lost: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return (self.outcome == "success" and self.recording_failure is None and not self.recording_losses
                and not self.analytics_lost)


_STARTED_RAY = False
#: stop signals received (SIGINT/SIGTERM through :func:`request_stop`), and whether raising KeyboardInterrupt in the
#: main thread is safe right now: while the application is built and while a mission runs, yes; while actors are
#: being set up or torn down, no (an exception inside a Ray call there can leave the core worker half shut down and
#: abort the process: exit 134 instead of 143, the recording unfinished) — the stop is then taken at the next
#: safe point, which ends the mission as ``interrupted`` with the recording finished
STOP_SIGNALS: list[int] = []
_RAISE_OK = [True]
#: True while :func:`run_mission` runs (a stop signal then ends the mission); after it, a signal that comes once a
#: mission's summary was printed does not change the run's exit code (see ``aerodaas run``)
IN_MISSION = [False]


def allow_stop_interrupt(allowed: bool) -> None:
    """Whether a stop signal (:func:`request_stop`) may raise KeyboardInterrupt in the main thread from now on:
    True while the application is built, False around Ray's shutdown (see :data:`STOP_SIGNALS`)."""
    _RAISE_OK[0] = bool(allowed)


def request_stop(signum: int) -> None:
    """Called by the CLI's SIGINT/SIGTERM handler (main thread): record the stop and raise KeyboardInterrupt when
    that is safe now; otherwise the run stops at its next safe point."""
    STOP_SIGNALS.append(signum)
    if _RAISE_OK[0]:
        raise KeyboardInterrupt(f"signal {signum}")
_EARLY: dict[str, Any] = {}  # the background start of Ray (start_ray_early)


#: True when this run attached to the cluster of `aerodaas up` (a local cluster, placed as local mode is)
_ATTACHED_UP = False


def _up_address() -> str | None:
    """The address of a running `aerodaas up` cluster, unless ``AERODAAS_NO_ATTACH=1``."""
    if os.environ.get("AERODAAS_NO_ATTACH") == "1":
        return None
    from aerodaas.clusters.persistent import attached_address

    return attached_address()


def init_ray(address: str | None) -> None:
    """Start or join Ray for this driver: join the cluster at ``address`` (``ray://`` or ``host:port``); else
    attach to the persistent local cluster of ``aerodaas up`` if one runs; else start a fresh loopback-only local
    Ray of our own (:func:`aerodaas.clusters.loopback.loopback_only`), retried up to 3 times when Ray's startup
    times out on a loaded machine. Installed plug-in packages are shipped to a cluster joined or attached to
    (``AERODAAS_SHIP_PLUGINS=0``: not). Raises what ``ray.init`` raises. Called by :func:`ensure_ray` /
    :func:`start_ray_early`."""
    global _STARTED_RAY
    import ray

    up_address = None if address else _up_address()
    # installed plug-in packages (entry points) travel to a cluster we attach to: its nodes may not have them
    from aerodaas.plugins.registry import plugin_package_paths

    ship = plugin_package_paths() if (address or up_address) and os.environ.get("AERODAAS_SHIP_PLUGINS") != "0" \
        else []
    if up_address:  # not what `aerodaas up`'s workers import already: their warm pool serves jobs without one
        from aerodaas.clusters.persistent import not_on_cluster_path

        ship = not_on_cluster_path(ship)
    renv = {"runtime_env": {"py_modules": ship}} if ship else {}
    if address:
        ray.init(address=address, log_to_driver=True, include_dashboard=False, **renv)
    elif up_address:
        # the persistent local cluster of `aerodaas up` (aerodaas.clusters.persistent): loopback, like our own
        from aerodaas.clusters.local import enable_token_auth

        enable_token_auth()  # the cluster was started with token auth: the driver must present the token
        from aerodaas.clusters.persistent import await_fresh_workers

        if not await_fresh_workers():
            print("aerodaas: warning: the local cluster's warm workers still hold framework code older than this "
                  "driver's; `aerodaas down && aerodaas up` restarts them", file=sys.stderr, flush=True)
        restore = loopback_only()
        try:
            ray.init(address=up_address, log_to_driver=True, configure_logging=True, logging_level="warning", **renv)
        finally:
            restore()
        global _ATTACHED_UP
        _ATTACHED_UP = True
        print(f"aerodaas: attached to the local cluster of `aerodaas up` at {up_address} (`aerodaas down` stops it)",
              file=sys.stderr, flush=True)
    else:
        # address="local": always a fresh cluster of our own, never one that `ray start` left on this machine
        # num_cpus=3: the run's actors reserve no CPU (num_cpus=0), so the CPU resource only sizes Ray's pool of
        # workers prestarted while the app is built: three, which the recorder, a drone and an analytics actor take
        # (1.4 s instead of 2.0 s from Ray ready to the actors ready, `aerodaas bench startup`)
        dashboard = OPTIONS.dashboard
        from aerodaas.clusters.worker_memory import limit_malloc_arenas

        limit_malloc_arenas()  # the workers' C heap: see the module
        from aerodaas.clusters import reaper

        reaper.ensure_started()  # Ray's processes end with this driver, however it ends (see the module)
        for attempt in range(3):
            try:
                restore = loopback_only()
                # the dashboard (loopback only) serves `ray list actors` and the actor view of the run
                # worker_niceness 0: drone actors fly the vehicles; Ray's default niceness 15 would let any other
                # process on the machine (a SITL autopilot, a compiler) starve their control loops
                ray.init(address="local", labels={"tier": "edge"}, include_dashboard=dashboard,
                         dashboard_host="127.0.0.1", log_to_driver=True, _system_config={"worker_niceness": 0},
                         num_cpus=3, configure_logging=True, logging_level="warning")
                restore()
                break
            except Exception as e:  # noqa: BLE001 - Ray raises a bare Exception for this one
                restore()
                # Ray gives its raylet a fixed 30 s to register with the GCS (ray/_private/node.py); a heavily
                # loaded machine can miss that: start again (at most 3 times) rather than fail the run. A dashboard
                # that fails to start is not worth failing the run for: start again without it
                ray.shutdown()
                if dashboard and "dashboard" in str(e).lower() and attempt < 2:
                    print(f"aerodaas: warning: Ray's dashboard did not start ({str(e).splitlines()[0][:120]}); "
                          f"running without it", file=sys.stderr, flush=True)
                    dashboard = False
                    continue
                if "timed out during startup" not in str(e) or attempt == 2:
                    raise
        _STARTED_RAY = True


def start_ray_early(address: str | None = None) -> None:
    """Start (or connect to) Ray in a background thread while the application is imported and built; the next
    :func:`ensure_ray` waits for it. Ray's processes are tied to the thread that started them
    (``PR_SET_PDEATHSIG``), so that thread stays alive, idle, for the life of the driver."""
    import threading

    if _EARLY:
        return
    ready = threading.Event()
    _EARLY.update(ready=ready, error=None, address=address)

    def keeper() -> None:
        import logging

        class _NoSigtermNotice(logging.Filter):  # the CLI installs its own SIGTERM handler in the main thread
            def filter(self, record: logging.LogRecord) -> bool:
                return not str(record.msg).startswith("SIGTERM handler is not set")

        logging.getLogger("ray._private.worker").addFilter(_NoSigtermNotice())
        try:
            init_ray(address)
        except BaseException as e:  # surfaced by ensure_ray in the main thread
            _EARLY["error"] = e
        ready.set()
        threading.Event().wait()

    threading.Thread(target=keeper, name="aerodaas-ray-keeper", daemon=True).start()


class PlanReady(Exception):
    """Raised by :func:`run_mission` under ``OPTIONS.plan_only`` (``aerodaas plan``): ``plan`` is the
    :class:`aerodaas.runtime.dataflow.RunPlan` the run would start; nothing was started."""

    def __init__(self, plan: Any) -> None:
        super().__init__(f"plan of run {plan.run_id}")
        self.plan = plan


class RayStartError(RuntimeError):
    """Ray could not be started or reached (the message says which and why); ``aerodaas run`` exits 1 with it."""


class RayAddressError(RayStartError):
    """The Ray cluster of ``--address`` could not be reached (bad input: ``aerodaas run`` exits 2 naming it)."""


def ensure_ray(address: str | None = None) -> bool:
    """Connect to (``address``) or start a local Ray; returns True when the cluster has ``tier=cloud`` nodes.
    Raises :class:`RayStartError`."""
    import ray

    where = f"the Ray cluster at {address!r}" if address else "a local Ray"
    if _EARLY and _EARLY["address"] == address:
        _EARLY["ready"].wait()
        if _EARLY["error"] is not None:
            err, _EARLY["error"] = _EARLY["error"], None
            _EARLY.clear()
            if isinstance(err, KeyboardInterrupt):
                raise err
            raise (RayAddressError if address else RayStartError)(f"could not start {where}: {type(err).__name__}: {err}") from err
    if not ray.is_initialized():
        try:
            init_ray(address)
        except Exception as e:  # noqa: BLE001 - Ray raises bare Exceptions (node start time-outs, ...)
            raise (RayAddressError if address else RayStartError)(f"could not start {where}: {type(e).__name__}: {e}") from e
    return any(n.get("Labels", {}).get("tier") == "cloud" for n in ray.nodes() if n.get("Alive"))


def shutdown_ray() -> None:
    global _STARTED_RAY
    import ray

    if _EARLY:
        _EARLY["ready"].wait()
    if _STARTED_RAY and ray.is_initialized():
        ray.shutdown()
    _STARTED_RAY = False
    _EARLY.clear()


def _start_scheduling(env, plan, scheduled: dict, has_cloud: bool) -> list:
    """Start the cloud executors of the analytics scheduler (tier=cloud nodes, or this node without any) running
    copies of the scheduled analytics, and give every dispatcher actor of the plan (one per edge compute) the
    scheduler's spec. Returns the executors' handles (to kill at the end)."""
    from aerodaas.actors.cloud_executor import cloud_selector, start_cloud_executors
    from aerodaas.protocol.specs import AnalyticsSchedulerSpec
    from aerodaas.schedulers.analytics_base import analytics_scheduler_class

    cfg = env.cfg.analytics_scheduler
    policy_class = analytics_scheduler_class(cfg.name)  # the class travels, not its name
    analytics = {a.name: a for a in scheduled.values()}
    executors = start_cloud_executors(cfg.cloud_executors, mode="real", selector=cloud_selector(has_cloud),
                                      name_prefix="cloud-analytics", analytics=analytics,
                                      ray_name_prefix=f"aerodaas/{plan.run_id}/cloud-analytics/")
    for a in plan.actors.values():
        if a.role == "dispatcher":
            a.spec.analytics_scheduler = AnalyticsSchedulerSpec(
                cfg.name, policy_class, cfg.resolved_workload(env.cfg), executors, list(cfg.network),
                cfg.jpeg_quality, 0)
    return executors


def _bind_handles(plan, actors: dict, robots: list, graphs: dict, env) -> dict:
    """The driver's handles per robot (drone, scheduler, cameras, analytics: :class:`ComponentHandle` into their
    actors), bound to the application's objects (``Robot.bind_drone``, live scheduler, pull getters)."""
    import ray

    from aerodaas.runtime.handles import AnalyticsHandle, CameraHandle, DroneHandle, SchedulerHandle

    loc = plan.location()
    handles: dict[str, dict] = {}
    for r in robots:
        ids = plan.robots[r.id]
        a_handles = {cid: AnalyticsHandle(actors[loc[cid]], cid) for cid in ids["analytics"]}
        home = actors[ids["actor"]]
        handles[r.id] = {"robot": r, "drone": DroneHandle(home, ids["drone"]),
                         "scheduler": SchedulerHandle(home, ids["scheduler"]), "analytics": a_handles,
                         "cameras": {sid: CameraHandle(home, cid) for sid, cid in ids["cameras"].items()},
                         "sched_obj": r.scheduler or env.trajectory_scheduler()}
        r.bind_drone(handles[r.id]["drone"])
        for s in r.sensors.values():
            s.get_data_stream().bind_runtime(_pull_getter(s, handles[r.id]))
        for a in graphs[r.id]:
            mine = [c for c in plan.analytics_instances[id(a)] if c in a_handles]
            if mine:
                h = a_handles[mine[0]]
                a.output.bind_runtime(lambda h=h: ray.get(h.get_latest.remote()))
    return handles


def run_mission(env, robots: list, timeout: float | None = None) -> MissionResult:
    """Plan the run's actors (:mod:`aerodaas.runtime.dataflow`), start them, fly (:func:`aerodaas.runtime.supervise.supervise`),
    finish the recording and tear down. Bad input raises before Ray starts; once actors exist, every failure ends
    in a :class:`MissionResult` (never a raw traceback) with the recording finished."""
    IN_MISSION[0] = True
    try:
        return _run_mission(env, robots, timeout)
    finally:
        IN_MISSION[0] = False


def _run_mission(env, robots: list, timeout: float | None) -> MissionResult:
    import ray

    from aerodaas.runtime.dataflow import Placement, build_plan
    from aerodaas.runtime.supervise import collect_stats, start_actors, supervise

    opts = OPTIONS
    timeout = opts.timeout if opts.timeout is not None else timeout
    sim = SimulationConfig.model_validate(env.cfg.simulation.model_dump())
    if opts.speedup is not None:
        sim.speedup = opts.speedup
    if opts.lockstep is not None:
        sim.lockstep = opts.lockstep
    check_clocks(robots, sim)
    graphs, scheds, scheduled = validate(env, robots, opts)

    from aerodaas.protocol.startup_probe import probe

    probe("app_built")
    t_start = time.monotonic()
    if opts.plan_only:
        raise PlanReady(build_plan(env, robots, graphs, scheds, sim, record=opts.record, live=opts.live,
                                   scheduled=scheduled))
    if STOP_SIGNALS:  # stopped while the app was built: nothing started, nothing to record
        raise KeyboardInterrupt(f"signal {STOP_SIGNALS[0]}")
    allow_stop_interrupt(False)  # from here on a stop signal is taken at the safe points (see request_stop)
    has_cloud = ensure_ray(opts.address)
    probe("ray_ready")
    epoch_ns = time.time_ns()
    from aerodaas.plugins.registry import by_value_modules

    for mod in by_value_modules():  # plug-ins reached by an import path outside any installed package
        ray.cloudpickle.register_pickle_by_value(sys.modules[mod])
    plan = build_plan(env, robots, graphs, scheds, sim, record=opts.record, live=opts.live, scheduled=scheduled,
                      epoch_ns=epoch_ns, run_id=opts.run_id or os.environ.get("AERODAAS_RUN_ID") or None)
    placement = Placement(has_cloud=has_cloud, local=(_STARTED_RAY or _ATTACHED_UP) and not opts.address)
    if not placement.local:
        from aerodaas.clusters.placement import placement_warning

        warning = placement_warning(plan)
        if warning:
            print(f"aerodaas: warning: {warning}", file=sys.stderr, flush=True)
    if opts.progress:
        kinds = {}
        for a in plan.actors.values():
            kinds[a.role] = kinds.get(a.role, 0) + 1
        # `ray list actors` talks to the dashboard's state API, so the hint names the dashboard, not the GCS
        dashboard_url = ray._private.worker.get_dashboard_url() if (OPTIONS.dashboard or opts.address) else ""
        print(f"aerodaas: run {plan.run_id}: " + ", ".join(f"{n} {k}" for k, n in kinds.items()) + " actor(s) on Ray "
              f"{ray.get_runtime_context().gcs_address}" + (f" (see them: RAY_AUTH_MODE=token ray list actors --address "
              f"http://{dashboard_url})" if dashboard_url else
              " (run with --dashboard to see them with `ray list actors`)"), flush=True)
    actors: dict[str, Any] = {}
    cloud_executors: list = []
    handles: dict[str, dict] = {}
    hitl = None
    reports: dict[str, dict] = {}
    stats: dict[str, Any] = {}
    latency: dict[str, Any] = {}
    counts: dict[str, int] = {}
    rec_report: dict[str, Any] = {}
    failure: str | None = None
    robot_errors: dict[str, str] = {}  # robot id -> its own error when the run could not start
    try:
        try:
            if scheduled:
                cloud_executors = _start_scheduling(env, plan, scheduled, has_cloud)
            actors = start_actors(plan, placement, env.cfg.actor_max_restarts)
            probe("actors_created")
            # every actor sets up at once (drones connect to their vehicles); the recorder's answer is read first:
            # a bad file or live view is the error reported
            rec_setup = actors["recorder"].setup.remote()
            others = [h.setup.remote() for hid, h in actors.items() if hid != "recorder"]
            ray.get(rec_setup)
            described, first = [], None
            for ref in others:  # every actor's answer: each robot that could not connect gets its own error
                try:
                    described.append(ray.get(ref))
                except Exception as e:  # noqa: BLE001
                    per = getattr(getattr(e, "cause", None), "errors", None) or getattr(e, "errors", None)
                    if isinstance(per, dict):
                        robot_errors.update(per)
                    first = first or e
            if first is not None:
                raise first
        except KeyboardInterrupt:
            raise
        except Exception as e:  # noqa: BLE001 - e.g. a vehicle that does not answer: a failed run, not a traceback
            failure = _cause(e)
            for rid, err in robot_errors.items():
                print(f"aerodaas: robot {rid!r} could not start: {err}", file=sys.stderr, flush=True)
            print(f"aerodaas: the run could not start: {failure}", file=sys.stderr, flush=True)
            described = []
        for d in [ray.get(actors["recorder"].setup.remote())] if "recorder" in actors and failure is None else []:
            if d.get("live_url"):
                print(f"aerodaas: live view at {d['live_url']} (Foxglove: Open connection -> Foxglove WebSocket)",
                      flush=True)
        probe("hosts_ready")
        if failure is None:
            handles = _bind_handles(plan, actors, robots, graphs, env)
            for r in robots:
                h = handles[r.id]
                if scheds[r.id] is h["sched_obj"]:  # not shared: live add/clear go to this robot's queue
                    h["sched_obj"].bind_remote(h["scheduler"])
            hcfg = env.cfg.hitl
            if opts.hitl if opts.hitl is not None else hcfg.enabled:
                from aerodaas.tools.hitl import HitlServer

                hitl = HitlServer({rid: {"drone": h["drone"], "scheduler": h["scheduler"]}
                                   for rid, h in handles.items()}, host=hcfg.host,
                                  port=opts.hitl_port if opts.hitl_port is not None else hcfg.port,
                                  token=hcfg.token, docs=hcfg.docs).start()
                env.hitl = hitl
                shown = hitl.token if hitl.generated_token else "(the token from environment.json)"
                print(f"aerodaas: human-in-the-loop API at {hitl.url}  bearer token: {shown}", flush=True)
            for h in handles.values():
                h["robot"].run_start_hooks()
            allow_stop_interrupt(True)
            t_fly = time.monotonic()
            reports = supervise(plan, actors, handles, timeout, opts.progress, lambda: bool(STOP_SIGNALS),
                                restart_wait_s=env.cfg.actor_restart_timeout_s)
            fly_s = time.monotonic() - t_fly
            allow_stop_interrupt(False)
            stats, latency = collect_stats(handles, actors, plan)
            if not stats["_settle"]["idle"]:
                print(f"aerodaas: warning: messages were still in flight between actors after "
                      f"{stats['_settle']['s']:.0f} s; the counts below may leave them out", file=sys.stderr, flush=True)
            # the flying part alone (actors started and wired, until the mission ended), s: what benchmarks measure
            stats["_timing"] = {"mission_s": round(fly_s, 3), "startup_s": round(t_fly - t_start, 3)}
            stats["_plan"] = {"run": plan.run_id, "actors": {hid: a.name for hid, a in plan.actors.items()},
                              "placed": {d.get("host"): d.get("node_id") for d in described}}
    finally:
        allow_stop_interrupt(False)
        if hitl is not None:
            hitl.stop()
            env.hitl = None
        counts, rec_report = _close_actors(actors, opts.record)
        for h in handles.values():
            h["robot"].bind_drone(None)
            h["sched_obj"].bind_remote(None)
            for s in h["robot"].sensors.values():
                s.get_data_stream().bind_runtime(None)
        for h in [*actors.values(), *cloud_executors]:
            try:
                ray.kill(h, no_restart=True)
            except Exception:  # noqa: BLE001 - an actor on a lost node is already gone
                pass
    allow_stop_interrupt(True)  # back in the application
    for r in robots:
        err = robot_errors.get(r.id) or (f"not started: another robot could not connect ({failure})"
                                         if robot_errors else failure) or "no report (the run did not start)"
        reports.setdefault(r.id, {"robot": r.id, "outcome": "failed", "error": err})
    outcomes = [rep.get("outcome") or "failed" for rep in reports.values()]
    outcome = "success" if outcomes and all(o == "success" for o in outcomes) else next(
        (o for o in outcomes if o != "success"), "failed")
    if outcome == "success" and rec_report.get("losses"):
        outcome = "recording_lost"  # the drones finished, but the run's truth has a hole: not a success
    lost_analytics = sorted({cid for h in (stats.get("_hosts") or {}).values() if isinstance(h, dict)
                             for cid in h.get("lost_consumers", [])}) if isinstance(stats, dict) else []
    if outcome == "success" and lost_analytics:
        outcome = "analytics_lost"  # the drones finished, flying on without an analytics that never came back
    result = MissionResult(outcome=outcome, robots=reports, stats=stats, latency=latency, recording=opts.record,
                           wall_s=time.monotonic() - t_start, recording_counts=counts,
                           recording_failure=rec_report.get("failure"), recording_lost=rec_report.get("lost", 0),
                           recording_start_ns=epoch_ns, recording_losses=rec_report.get("losses") or [],
                           recording_segments=rec_report.get("segments") or [],
                           recording_segment_messages=rec_report.get("segment_messages") or [],
                           recording_duplicates=rec_report.get("duplicates", 0), analytics_lost=lost_analytics)
    for h in handles.values():
        h["robot"].run_end_hooks(result)
    return result


def _close_actors(actors: dict, record: str | None) -> tuple[dict, dict]:
    """Close every actor (analytics and dispatchers first, drones, the recorder last: everything they recorded
    reaches the file); returns (message counts, recording report). Never raises."""
    import ray

    order = sorted((h for h in actors if h != "recorder"), key=lambda h: h.startswith("drone"))
    pings = {hid: actors[hid].ping.remote() for hid in order}
    alive = set()
    for hid, ref in pings.items():  # an actor whose node is gone (pending a restart that cannot happen) is skipped
        try:
            ray.get(ref, timeout=10)
            alive.add(hid)
        except Exception:  # noqa: BLE001
            print(f"aerodaas: warning: actor {hid!r} is gone (not closed; the recording has what it sent)",
                  file=sys.stderr)
    order = [h for h in order if h in alive]
    refs = {}
    for hid in order:
        try:
            refs[hid] = actors[hid].close.remote()
        except Exception:  # noqa: BLE001
            pass
    for hid, ref in refs.items():
        try:
            ray.get(ref, timeout=60)
        except Exception as e:  # noqa: BLE001 - a dead actor has nothing left to close
            if not isinstance(e, ray.exceptions.RayActorError):
                print(f"aerodaas: warning: actor {hid!r} could not be closed cleanly: {_cause(e)}", file=sys.stderr)
    counts: dict = {}
    rep: dict = {}
    if "recorder" in actors:
        try:
            counts = ray.get(actors["recorder"].close.remote(), timeout=120)
            rep = ray.get(actors["recorder"].recording_report.remote(), timeout=60)
        except ray.exceptions.RayActorError as e:  # it died while closing (its node with it): finish it here
            loss = {"segment": record, "recorded_until_ns": None, "previous_finished": False,
                    "error": f"the recorder actor died while closing: {_cause(e)}"}
            rep = {"losses": [loss]}
            counts = _finish_orphaned_recording(record, loss)
            how = f"finished it here: {sum(counts.values())} messages" if loss["previous_finished"] else \
                f"run `aerodaas recover {record}`"
            print(f"aerodaas: warning: the recorder actor died while closing the recording {record} ({how})",
                  file=sys.stderr)
        except Exception as e:  # noqa: BLE001 - pragma: no cover - reported, never silently lost
            print(f"aerodaas: warning: the recorder could not be closed cleanly (recording: {record}): {_cause(e)}",
                  file=sys.stderr)
    return counts, rep


def _finish_orphaned_recording(record: str | None, loss: dict) -> dict[str, int]:
    """The recording of a recorder actor that died with its node, finished by the driver when the file is on this
    machine (local mode, `aerodaas up`): rewritten as a finished MCAP (:func:`aerodaas.recording.recover.
    recover_mcap`, what ``aerodaas recover`` does), ``loss`` updated with ``recorded_until_ns`` and
    ``previous_finished``. Returns the per-topic message counts it holds ({} when the file is not here or cannot
    be read; then ``loss["finish_error"]`` says why)."""
    if not record or not os.path.isfile(record):
        return {}
    from aerodaas.recording.reader import summarize_mcap
    from aerodaas.recording.recover import recover_mcap

    try:
        recover_mcap(record)
        summary = summarize_mcap(record)
    except (OSError, ValueError) as e:
        loss["finish_error"] = f"{type(e).__name__}: {e}"
        return {}
    loss["recorded_until_ns"] = summary.get("end_ns")
    loss["previous_finished"] = True
    return {c["topic"]: c["count"] for c in summary.get("channels", [])}


def _pull_getter(sensor, h: dict):
    import ray

    from aerodaas.config.robot import sensor_class
    from aerodaas.plugins.sensor import SensorDelivery

    delivery = sensor_class(sensor.type).delivery

    def get():
        if delivery is SensorDelivery.CAMERA and sensor.id in h["cameras"]:
            return ray.get(h["cameras"][sensor.id].get_latest.remote())
        st = ray.get(h["drone"].status.remote())
        return st if delivery is SensorDelivery.MISSION_STATUS else ray.get(h["drone"].report.remote()).get("position")

    return get
