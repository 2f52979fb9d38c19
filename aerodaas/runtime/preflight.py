"""Everything checked before any actor of a run starts (``aerodaas run`` and ``start_mission``): the recording's
path, each robot's trajectory scheduler (a fork per robot of a shared one), its pre-planned missions against its
safety limits, an autopilot mission's shape, the clocks (lock-step needs simulated vehicles), each analytics' output
contract (its declared messages, and ``consumes`` against the streams that feed it) and the analytics the
analytics scheduler places per frame. Each check raises ConfigError / ValueError / SafetyViolation naming the field
and the value; nothing here starts Ray."""
from __future__ import annotations

import sys
from typing import Any

from aerodaas.analytics.contract import check_consumes, check_declaration
from aerodaas.backends import backend_class, backend_clock
from aerodaas.clusters.addresses import check_hitl, check_ray_address
from aerodaas.clusters.tls import ServeAccess, check_exposure, is_loopback
from aerodaas.config import ConfigError, MAX_SPEEDUP, MIN_SPEEDUP, SimulationConfig, load_environment_config
from aerodaas.config.robot import sensor_class
from aerodaas.model.ids import check_analytics_names
from aerodaas.model.types import AeroNavigation, SchedulingType
from aerodaas.navigation.safety import SafetyGate
from aerodaas.perception.providers import missing_here
from aerodaas.recording.record_path import RunInput, check_record_path
from aerodaas.runtime.dataflow import collect_graph
from aerodaas.sim.ground_cache import limit_bytes

__all__ = ["validate", "validate_graph", "check_options", "check_deployment", "simulation_for", "check_clocks",
           "check_timeout", "MAX_TIMEOUT_S", "robot_schedulers", "scheduled_analytics", "check_preplanned",
           "check_required_providers"]


def scheduled_analytics(env, graphs: dict) -> dict[int, Any]:
    """The analytics the environment's analytics scheduler places per frame (id -> analytics): those named in
    ``analytics_scheduler.models``. Raises ConfigError for a named analytics the application does not have, two
    scheduled analytics sharing a name, or one that is not fed by camera frames."""
    cfg = env.cfg.analytics_scheduler
    if cfg.name == "default":
        return {}
    every = {id(a): a for g in graphs.values() for a in g}
    out = {i: a for i, a in every.items() if a.name in cfg.models}
    names = [a.name for a in out.values()]
    for name in cfg.models:
        if name not in names:
            raise ConfigError(f"analytics_scheduler.models.{name}: the application has no analytics named {name!r} "
                              f"(it has {sorted({a.name for a in every.values()})})")
        if names.count(name) > 1:
            raise ConfigError(f"analytics_scheduler.models.{name}: {names.count(name)} analytics share the name "
                              f"{name!r}; give each scheduled analytics its own name")

    def camera(src) -> bool:  # a sensor whose class delivers camera frames (an analytics' output is not)
        type_ = getattr(src, "type", None)
        try:
            return isinstance(type_, str) and sensor_class(type_).delivery.frames
        except ValueError:
            return False

    for a in out.values():
        bad = [getattr(st.source, "id", repr(st.source)) for st in a.inputs if not camera(st.source)]
        if bad or not a.inputs:
            raise ConfigError(f"analytics_scheduler.models.{a.name}: a scheduled analytics takes camera frames, but "
                              f"{a.name!r} is fed by {bad or 'nothing'}")
    return out


def robot_schedulers(env, robots: list) -> dict[str, Any]:
    """Each robot's trajectory scheduler. Robots that share one scheduler object (the application plugged one into
    the environment) get a fork each, holding the missions that robot navigates. Raises ValueError for a queued
    mission that no robot navigates when several robots share the scheduler (its drone would be a guess)."""
    by_sched: dict[int, list] = {}
    for r in robots:
        by_sched.setdefault(id(r.scheduler or env.trajectory_scheduler()), []).append(r)
    out: dict[str, Any] = {}
    for group in by_sched.values():
        sched = group[0].scheduler or env.trajectory_scheduler()
        if len(group) == 1:
            out[group[0].id] = sched
            continue
        owned: dict[str, list] = {r.id: [] for r in group}
        for m in sched.missions():
            owners = [r for r in group if any(w is i for nav in r.navigations for w in nav.waypoints for i in m.items)]
            if not owners:
                raise ValueError(f"mission {m.name!r} (priority {m.priority}) is queued in the shared trajectory scheduler "
                                 f"but no robot navigates it; call robot.navigate(...) for one of "
                                 f"{[r.id for r in group]}")
            owned[owners[0].id].append(m)
        for r in group:
            out[r.id] = sched.fork(owned[r.id])
    return out


def validate_graph(env, robots: list) -> tuple[dict, dict, dict]:
    """The checks of the application itself, whatever the run's options (done when it is loaded,
    :mod:`aerodaas.runtime.app_loader`): each robot's analytics (names, deployment, options), its trajectory
    scheduler and pre-planned missions, an autopilot mission's shape, the analytics scheduler's analytics and the
    clocks under the environment's simulation settings. Returns (graphs, schedulers, scheduled analytics). Raises
    ConfigError / ValueError / SafetyViolation naming the field."""
    simulation_for(env, robots, None)
    graphs = {}
    scheds = robot_schedulers(env, robots)
    for r in robots:
        analytics = collect_graph(r)
        try:  # its name is part of its topics (/<robot>/<name>/detections): the id grammar, one name per analytics
            check_analytics_names(r.id, [(a.name, type(a).__name__) for a in analytics], [s.id for s in r.cfg.sensors])
        except ValueError as e:
            raise ConfigError(f"{e}; each analytics of a robot records under its own name: give it name=...") from None
        for a in analytics:
            if a.compute is None:
                a.deploy(env.get_compute_resources()[0])
            check_deployment(env, a)
            check = getattr(a, "check", None)
            if callable(check):
                check()
            if getattr(a, "on_error", "continue") not in ("continue", "abort"):
                raise ConfigError(f"analytics {a.name!r}: on_error must be 'continue' or 'abort', got "
                                  f"{getattr(a, 'on_error')!r}")
            check_failure_fraction(a)
            if getattr(a, "num_gpus", 0.0) and getattr(a, "colocate", False):
                raise ConfigError(f"analytics {a.name!r}: asks Ray for num_gpus={a.num_gpus:g} (its providers), but "
                                  f"deploy(..., colocate=True) runs it inside each drone's actor, which asks for "
                                  f"none; deploy it on its own actor, or set Providers(num_gpus=0)")

            check_declaration(a)  # Output / named_outputs / consumes well-formed (ContractError, a ValueError)
            check_consumes(a)  # each feeding stream carries a type it consumes
        graphs[r.id] = analytics
        check_preplanned(r, scheds[r.id])

        backend_class(r.cfg.backend).check_mission(r, scheds[r.id], env.cfg.hitl.enabled)
    scheduled = scheduled_analytics(env, graphs)
    for a in scheduled.values():
        if getattr(a, "num_gpus", 0.0):
            raise ConfigError(f"analytics_scheduler.models.{a.name}: {a.name!r} asks Ray for num_gpus={a.num_gpus:g} "
                              f"(its providers), but the analytics scheduler runs it in its dispatcher and cloud "
                              f"actors, which ask for none; set Providers(num_gpus=0) or do not schedule it")
    return graphs, scheds, scheduled


def check_deployment(env, analytics) -> None:
    """``analytics`` is deployed on one of ``env``'s compute resources (``deploy(compute)`` with what
    ``env.get_compute_resource_by_id`` returns). Raises ConfigError naming the analytics and the value given: a name
    (``deploy("edge")``, or ``analytics.compute = "edge"``) or another object failed after Ray started, as an
    AttributeError reported as a bug of AeroDaaS."""
    comp, known = analytics.compute, env.get_compute_resources()
    if any(comp is c for c in known):
        return
    same = [c for c in known if c.id == getattr(comp, "id", None) and c.tier == getattr(comp, "tier", None)]
    if same and getattr(comp, "cfg", None) == same[0].cfg:  # the same resource of another Environment of the file
        return
    ids = [c.id for c in known]
    hint = f"; use env.get_compute_resource_by_id({comp!r})" if isinstance(comp, str) and comp in ids else ""
    raise ConfigError(f"analytics {analytics.name!r}: deployed on {type(comp).__name__} {comp!r}, which is not a "
                      f"compute resource of this environment (it has {ids}){hint}")


def check_options(env, robots: list, scheds: dict, opts: Any, *, inputs: tuple = ()) -> SimulationConfig:
    """The checks of a run's options (``opts``: :class:`~aerodaas.runtime.options.RunOptions`) against the
    application, before Ray starts: the HITL API's host and port, the recording's path (never one of the run's
    ``inputs`` — the app file —, the environment file, whoever named it: ``--env`` or the app's
    ``Environment("x.json")``, nor any file the environment names (:attr:`~aerodaas.config.EnvironmentConfig.
    files_read`: images, logs, recorded cameras, ``.plan`` files, keys, the HITL API's TLS files), even with
    ``--overwrite``), an autopilot mission with ``--hitl``, the clocks under ``--speedup`` / ``--lockstep``. Returns
    the run's simulation settings (:func:`simulation_for`). Raises ConfigError / ValueError naming the field or
    flag."""
    check_hitl(env.cfg, opts)  # the HITL API's host and port: parsed, in range, free
    access = hitl_access(env, opts, check=True)  # off loopback: HTTPS with good certificate and key files, or insecure
    if opts.record:
        named = [RunInput(f.path, f"{f.field} of the environment") for f in env.cfg.files_read]
        tls = [RunInput(str(q), flag) for q, flag in ((access.cert_file, "--tls-cert"), (access.key_file, "--tls-key"))
               if q]
        protect = (*(q for q in (*inputs, getattr(env.cfg, "source_file", None)) if q), *named, *tls)
        check_record_path(opts.record, overwrite=opts.overwrite, protect=protect)  # ValueError naming it: before Ray
    check_required_providers(robots, opts)
    if opts.hitl and not env.cfg.hitl.enabled:  # --hitl: a backend's mission may refuse the HITL API

        for r in robots:
            backend_class(r.cfg.backend).check_mission(r, scheds[r.id], True)
    return simulation_for(env, robots, opts)


def hitl_access(env, opts: Any, check: bool = False) -> Any:
    """The HITL API's TLS files and ``insecure`` choice as a :class:`aerodaas.clusters.tls.ServeAccess` (no token: the
    server holds its own): ``--tls-cert`` / ``--tls-key`` (``opts.tls_cert``/``tls_key``) over ``hitl.tls_cert`` /
    ``hitl.tls_key`` (resolved like every file of the environment), ``--insecure`` or ``hitl.insecure``;
    ``insecure`` is kept only when it matters (clear text off loopback). With ``check`` (before Ray starts) and the
    API on: :func:`aerodaas.clusters.tls.check_exposure`. Raises ConfigError / ValueError naming the field and value."""
    h = env.cfg.hitl
    if not (opts.hitl if getattr(opts, "hitl", None) is not None else h.enabled):
        return ServeAccess()
    files, fields = [], []
    for given, cfg_value, flag, name in ((getattr(opts, "tls_cert", None), h.tls_cert, "--tls-cert", "hitl.tls_cert"),
                                         (getattr(opts, "tls_key", None), h.tls_key, "--tls-key", "hitl.tls_key")):
        if given:
            files.append(given)
            fields.append(flag)
        else:
            files.append(str(env.cfg.resolve_path(cfg_value, name)) if cfg_value else None)
            fields.append(name)
    insecure = bool(getattr(opts, "insecure", False) or h.insecure)
    if check:
        check_exposure(h.host, files[0], files[1], insecure, "hitl.host", fields[0], fields[1],
                       "hitl.insecure or --insecure")
    return ServeAccess(files[0], files[1], None, insecure and files[0] is None and not is_loopback(h.host))


def check_required_providers(robots: list, opts: Any) -> None:
    """A run whose actors all run on this machine with this interpreter (no ``--address``, Ray not joined by the
    application): every onnxruntime provider an analytics requires (``Providers(required=True)``,
    :mod:`aerodaas.perception.providers`) is offered by this process's onnxruntime. Raises ConfigError naming the
    analytics and the provider; elsewhere the analytics' actor checks on its node and fails to start."""
    ray = sys.modules.get("ray")
    if getattr(opts, "address", None) or (ray is not None and ray.is_initialized()):
        return
    seen: set[int] = set()
    for r in robots:
        for a in collect_graph(r):
            prov = getattr(a, "providers", None)
            if id(a) in seen or not getattr(prov, "required", False):
                continue
            seen.add(id(a))

            missing = missing_here(prov)
            if missing:
                import onnxruntime as ort  # lazy: heavy onnxruntime

                raise ConfigError(f"analytics {a.name!r}: providers.required=True but this machine's onnxruntime "
                                  f"{ort.__version__} does not offer {missing} (it offers "
                                  f"{ort.get_available_providers()}); install onnxruntime-gpu / "
                                  f"onnxruntime-openvino in place of onnxruntime (docs/perception.md, "
                                  f"\"Accelerators\"), or set required=False for a CPU fallback")


def validate(env, robots: list, opts: Any) -> tuple[dict, dict, dict]:
    """:func:`validate_graph` and :func:`check_options` (``opts``: the run's
    :class:`~aerodaas.runtime.options.RunOptions`): returns (graphs, schedulers, scheduled analytics). Raises
    ConfigError / ValueError naming the field."""
    out = validate_graph(env, robots)
    check_options(env, robots, out[1], opts)
    return out


def simulation_for(env, robots: list, opts: Any) -> SimulationConfig:
    """The run's simulation settings: the environment's, ``opts.speedup`` / ``opts.lockstep`` over them (``opts``
    None: none), checked with :func:`check_clocks` (which sets a replay-only run's speed-up); ``recorder_hold_s``
    is 0 when a robot flies a real or emulated vehicle or a camera reads a video stream. Raises ConfigError."""
    sim = SimulationConfig.model_validate(env.cfg.simulation.model_dump())
    if opts is not None and opts.speedup is not None:
        sim.speedup = opts.speedup
    if opts is not None and opts.lockstep is not None:
        sim.lockstep = opts.lockstep
    hold = getattr(opts, "recorder_hold_s", None)
    if hold is not None:
        if not 0.0 <= hold <= 3600.0:  # also NaN
            raise ConfigError(f"--recorder-hold: {hold!r} s is outside [0, 3600]")
        sim.recorder_hold_s = float(hold)
    check_clocks(robots, sim)
    if any(backend_clock(r.cfg.backend) != "sim" for r in robots) or _stream_cameras(robots):
        sim.recorder_hold_s = 0.0  # real vehicles and video streams run on the wall clock: nothing can wait
    return sim


def _stream_cameras(robots: list) -> list[str]:
    """``robot/sensor`` of every camera that reads a video stream (on the wall clock)."""
    return [f"{r.id}/{s.id}" for r in robots for s in r.cfg.sensors
            if sensor_class(s.type).reads_wall_clock(s.properties)]


def check_clocks(robots: list, sim: SimulationConfig) -> None:
    """Real vehicles live in real time: lock-step needs every robot on the simulator. Raises ConfigError. A run
    that only replays logs runs its clock at the replay rate (so odometry keeps its rate in log time)."""
    rates = [backend_class(r.cfg.backend).clock_rate(r.cfg) for r in robots]
    if robots and all(x is not None for x in rates):  # e.g. every robot replays a log: its rate is the clock's
        sim.speedup = max(rates)

    live = _stream_cameras(robots)
    if live and (sim.speedup != 1.0 or sim.lockstep):
        raise ConfigError(f"simulation: the cameras {live} read a video stream, which runs on the wall clock: "
                          f"speedup must be 1 (got {sim.speedup:g}; also --speedup) and lockstep false (got "
                          f"{sim.lockstep})")
    real = [r.id for r in robots if backend_clock(r.cfg.backend) != "sim"]
    if real and sim.lockstep:
        raise ConfigError(f"simulation.lockstep: true needs every robot on backend 'sim'; {real} fly real or "
                          f"emulated vehicles, which cannot wait for the analytics (set lockstep to false)")


def check_preplanned(robot, sched) -> None:
    """Check every queued mission of ``robot`` against its safety limits before any actor starts (legs chained
    from the take-off point). Raises ConfigError for a navigation without items (the drone took off and hovered
    until the battery failsafe, 960 s) and for more pre-planned items than ``max_queued_items`` (the cap bounded only
    what was added in flight: 50,000 pre-planned waypoints were accepted), else
    :class:`aerodaas.navigation.safety.SafetyViolation`; clamped items replace the originals."""
    for nav in getattr(robot, "navigations", []):
        if isinstance(nav, AeroNavigation) and not nav.waypoints:
            raise ConfigError(f"robot {robot.id!r}: navigation {nav.name!r} holds no waypoints or commands "
                              f"(drone.navigate(...) of an empty AeroNavigation); the drone would take off and hover "
                              f"until its battery failsafe")
    cap, n = robot.cfg.max_queued_items, sched.pending()
    if n > cap:
        raise ConfigError(f"robots[{robot.id!r}].max_queued_items: {n} pre-planned navigation items, more than "
                          f"{cap} (the bound on everything queued for a robot; raise it in environment.json, at "
                          f"most 1000000)")

    gate = SafetyGate(robot.cfg.safety, robot.cfg.limits, robot.cfg.home)
    start = (0.0, 0.0, robot.cfg.takeoff_altitude)

    def check(m) -> list:
        nav = AeroNavigation(waypoints=list(m.items), scheduling_type=SchedulingType.ORDERED, name=m.name)
        return gate.check_navigation(nav, start).waypoints

    sched.revise_items(check)


def check_run_flags(record: str | None, env: str | None, speedup: float | None, timeout: float | None,
                    hitl_port: int | None, address: str | None, *, app: str | None = None,
                    overwrite: bool = False) -> None:
    """Everything ``aerodaas run``'s command line names, checked before Ray starts: no empty ``--record`` /
    ``--env``, a writable record path, ``--speedup`` / ``--timeout`` in range, ``--hitl-port`` in [0, 65535], the
    ``--address`` cluster reachable (:func:`aerodaas.clusters.addresses.check_ray_address`, within 10 s) and the
    ``--env`` file valid, and ``AERODAAS_GROUND_CACHE_MB`` a number >= 0. ``overwrite`` is for
    :func:`check_options`, which refuses an existing file that is not a recording once the application is loaded.
    Raises ValueError / ConfigError naming the flag (or variable) and the value."""
    limit_bytes()
    for flag, v in (("--record", record), ("--env", env)):
        if v is not None and not v.strip():
            raise ValueError(f"{flag} {v!r}: an empty path (leave the option out instead)")
    if record:
        # an existing file that is no recording is refused once the app is loaded (check_options): the environment
        # file the app opens itself is known only then, and is refused as an input, never with "pass --overwrite"
        check_record_path(record, overwrite=True, protect=tuple(q for q in (app, env) if q))

    for flag, v, lo, hi in (("--speedup", speedup, MIN_SPEEDUP, MAX_SPEEDUP),):
        if v is not None and not (v > lo and v <= hi or v == lo > 0):  # NaN fails every comparison
            raise ValueError(f"{flag} must be a number within {'[' if lo else '('}{lo:g}, {hi:g}], got {v!r}")
    check_timeout(timeout, "--timeout")
    if hitl_port is not None and not 0 <= hitl_port <= 65535:
        raise ValueError(f"--hitl-port {hitl_port}: outside [0, 65535] (0: any free port)")
    if address is not None:  # parsed, resolved and reachable within 10 s, before any Ray process

        check_ray_address(address, timeout_s=10.0)
    if env:
        load_environment_config(env)


#: the longest wall-clock limit of a mission, s (about 116 days): ``--timeout`` and ``start_mission(timeout=...)``
MAX_TIMEOUT_S = 1e7


def check_timeout(timeout: Any, name: str) -> None:
    """Refuse a mission's wall-clock limit ``timeout`` (seconds; None: no limit) that is not a number in
    (0, :data:`MAX_TIMEOUT_S`]: a bool, a string, NaN, 0, a negative number or an infinite one. The same rule
    for the command line's ``--timeout`` and the application's ``start_mission(timeout=...)`` (``name`` is what
    the message calls it). Raises ValueError naming ``name`` and the value, before Ray starts."""
    if timeout is None:
        return
    number = isinstance(timeout, (int, float)) and not isinstance(timeout, bool)
    if not number or not 0.0 < timeout <= MAX_TIMEOUT_S:  # NaN fails every comparison
        kind = "" if number else f" {type(timeout).__name__}"
        raise ValueError(f"{name} must be a number of wall-clock seconds within (0, {MAX_TIMEOUT_S:g}], got"
                         f"{kind} {timeout!r}")


def check_failure_fraction(a: Any) -> None:
    """Refuse an analytics whose ``max_failure_fraction`` is not a number in [0, 1] (ConfigError naming it)."""
    f = getattr(a, "max_failure_fraction", 0.0)
    if isinstance(f, bool) or not isinstance(f, (int, float)) or not 0.0 <= f <= 1.0:
        raise ConfigError(f"analytics {a.name!r}: max_failure_fraction must be a number in [0, 1] (the fraction of "
                          f"its items that may fail before the run is degraded), got {f!r}")
