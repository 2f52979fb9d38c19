"""The AeroDaaS application API (paper Table 2, in Python style): IEnvironment, IRobot, ISensor, ICompute.

Applications build a dataflow at module level (sensors -> analytics -> schedulers -> robot) and call
``robot.start_mission()``. Loaded by ``aerodaas run`` / ``plan`` / ``plugins`` (:mod:`aerodaas.runtime.app_loader`),
that call only marks where the mission starts: the application is a value the runner flies. Run as a plain script,
it starts the Ray actors, flies the mission and returns a :class:`aerodaas.runtime.driver.MissionResult`. Nothing
here starts Ray (an :class:`Environment` never does), so a malformed configuration or an invalid waypoint fails
before any actor starts.
"""
from __future__ import annotations

import dataclasses
import inspect
import os
from pathlib import Path
from typing import Any, Callable

from pydantic import ValidationError

from aerodaas.actors.builtin.source import BUILTIN
from aerodaas.backends import NotNavigable, is_navigable
from aerodaas.config import (AnalyticsSchedulerConfig, ComputeConfig, ConfigError, EnvironmentConfig, RobotConfig,
                             SensorConfig, _format_errors, load_environment_config)
from aerodaas.model.data import AeroStreamData
from aerodaas.model.types import AeroNavigation, PriorityQueue
from aerodaas.navigation.gimbal import GimbalError
from aerodaas.plugins import registry
from aerodaas.protocol.gimbal import GimbalPoint, GimbalRelease, GimbalRoi
from aerodaas.runtime.app_loader import env_path_override, is_sentinel, mark_mission
from aerodaas.runtime.options import RunOptions
from aerodaas.runtime.preflight import check_timeout
from aerodaas.schedulers import TrajectoryScheduler

__all__ = ["Environment", "Robot", "Sensor", "ComputeResource"]


def _fly(env: "Environment", robots: list["Robot"], timeout: float | None, options: Any = None):
    """While an application is loaded, mark its mission's start (:func:`aerodaas.runtime.app_loader.mark_mission`:
    nothing flies); else run the mission of ``robots`` under ``options`` (a
    :class:`~aerodaas.runtime.options.RunOptions`; None: the defaults) and return the MissionResult (blocks;
    ``aerodaas run`` is told each result by :func:`aerodaas.runtime.driver.run_file`). Raises ValueError naming
    ``start_mission(timeout=...)`` and the value for a ``timeout`` that is not a number of seconds in (0, 1e7] (the
    rule of ``--timeout``), before anything starts."""
    check_timeout(timeout, "start_mission(timeout=...)")
    marked = mark_mission(env, robots, timeout)
    if not is_sentinel(marked):
        return marked  # a mission of the application that already flew (loaded again after it)
    from aerodaas.runtime.driver import run_mission  # lazy: the runtime (~60 modules), only when a mission flies

    return run_mission(env, robots, with_builtin_actors(options), timeout)


def with_builtin_actors(options: Any = None) -> Any:
    """``options`` (a :class:`~aerodaas.runtime.options.RunOptions`; None: the defaults) with the built-in actors'
    source (:data:`aerodaas.actors.builtin.source.BUILTIN`) when it names no actor classes: the application API hands the
    runtime the actors it starts (the runtime imports no actor module), and the runtime imports them only once the
    application passed its checks. Imports neither Ray nor any actor module."""
    opts = options if options is not None else RunOptions()
    if opts.actors is not None:
        return opts
    return dataclasses.replace(opts, actors=BUILTIN)


class ComputeResource:
    """ICompute / IDeployable target: a compute resource on tier ``edge`` or ``cloud``."""

    def __init__(self, cfg: ComputeConfig) -> None:
        self.cfg = cfg
        self.id = cfg.id
        self.tier = cfg.tier

    def get_compute_properties(self) -> dict:
        """Processing power, memory, accelerators… as configured, plus ``tier``."""
        return {"tier": self.tier, **self.cfg.properties}

    def __repr__(self) -> str:
        return f"ComputeResource({self.id!r}, tier={self.tier!r})"


class Sensor:
    """ISensor (push and pull): a robot's or the environment's sensor."""

    def __init__(self, cfg: SensorConfig, robot: "Robot | None" = None) -> None:
        self.cfg = cfg
        self.robot = robot
        self._stream = AeroStreamData(source=self, buffer=cfg.buffer)

    @property
    def id(self) -> str:
        return self.cfg.id

    @property
    def type(self) -> str:
        return self.cfg.type

    def get_sensor_id(self) -> str:
        return self.cfg.id

    def get_sensor_property(self, prop: str) -> Any:
        """A configured property (e.g. ``fps``, ``width``); raises KeyError naming the sensor and property."""
        if prop == "type":
            return self.cfg.type
        if prop not in self.cfg.properties:
            raise KeyError(f"sensor {self.id!r} has no property {prop!r}; it has {sorted(self.cfg.properties)}")
        return self.cfg.properties[prop]

    def get_data_stream(self) -> AeroStreamData:
        """The sensor's stream (push: analytics subscribe to it; pull: ``get_data()`` while a mission runs)."""
        return self._stream

    def __repr__(self) -> str:
        return f"Sensor({self.id!r}, type={self.type!r})"


class Robot:
    """IRobot: a drone of the environment."""

    def __init__(self, cfg: RobotConfig, env: "Environment") -> None:
        self.cfg = cfg
        self.env = env
        self.id = cfg.id
        self.sensors = {s.id: Sensor(s, self) for s in cfg.sensors}
        self.navigations: list[AeroNavigation] = []
        self.scheduler = None
        self._start_hooks: list[Callable] = []
        self._end_hooks: list[Callable] = []
        self._handle = None  # the drone component's handle while running
        #: gimbal commands given before the mission started (carried out in order at take-off)
        self.gimbal_commands: list = []

    # -- sensors
    def has_sensors(self) -> bool:
        return bool(self.sensors)

    def get_sensors(self) -> list[Sensor]:
        return list(self.sensors.values())

    def get_sensor_by_id(self, sensor_id: str) -> Sensor:
        """Raises KeyError naming the robot and the known sensor ids."""
        try:
            return self.sensors[sensor_id]
        except KeyError:
            raise KeyError(f"robot {self.id!r} has no sensor {sensor_id!r}; it has {sorted(self.sensors)}") from None

    # -- navigation
    def is_navigable(self) -> bool:
        """False for a robot whose backend only reports (``replay`` of a recorded flight)."""
        return is_navigable(self.cfg.backend)

    def navigate(self, nav: AeroNavigation | PriorityQueue | Any) -> None:
        """Fly ``nav`` (usually the result of ``scheduler.generate_navigation``) with the environment's
        trajectory scheduler; navigation that the scheduler has not queued yet is queued now. Raises
        :class:`aerodaas.backends.NotNavigable` for a robot that cannot fly (``is_navigable()`` is False)."""
        if not self.is_navigable():
            raise NotNavigable(f"robot {self.id!r}: backend {self.cfg.backend!r} is not navigable "
                               f"(is_navigable() is False); it replays a recorded flight")
        sched = self.env.trajectory_scheduler()
        self.scheduler = sched
        data = nav.data if isinstance(nav, PriorityQueue) else nav
        if isinstance(data, AeroNavigation):
            queued = any(m.items and data.waypoints and m.items[0] is data.waypoints[0] for m in sched.missions())
            if not queued:
                sched.generate_navigation(nav)
        self.navigations.append(data)

    # -- mission lifecycle
    def on_mission_start(self, hook: Callable[["Robot"], None]) -> None:
        """startMission user hook: ``hook(robot)`` runs before take-off."""
        self._start_hooks.append(hook)

    def on_mission_end(self, hook: Callable[["Robot", Any], None]) -> None:
        """endMission user hook: ``hook(robot, result)`` runs after the mission ends."""
        self._end_hooks.append(hook)

    def bind_drone(self, handle: Any) -> None:
        """Bind the running mission's drone component ``handle`` (a :class:`~aerodaas.actors.builtin.handles.DroneHandle`,
        set by the driver once the actors run) so :meth:`end_mission`, :meth:`pause_mission` and
        :meth:`resume_mission` reach the vehicle; ``None`` when the run is over."""
        self._handle = handle

    def run_start_hooks(self) -> None:
        """Run the :meth:`on_mission_start` hooks, in the order they were added (the driver calls this before
        take-off). Raises what a hook raises; the hooks after it do not run."""
        for hook in self._start_hooks:
            hook(self)

    def run_end_hooks(self, result: Any) -> None:
        """Run the :meth:`on_mission_end` hooks with the run's MissionResult ``result``, in the order they were
        added. Raises what a hook raises; the hooks after it do not run."""
        for hook in self._end_hooks:
            hook(self, result)

    def start_mission(self, timeout: float | None = None, *, options: Any = None):
        """Start the actors, fly the mission to its end, and return the MissionResult (blocks); ``options``: the
        run's :class:`~aerodaas.runtime.options.RunOptions` (recording, speed-up, ...). ``timeout``: wall-clock
        seconds in (0, 1e7] from the mission's start, as ``aerodaas run --timeout`` (which wins when both are
        given); past it the mission ends with outcome ``timeout`` (``aerodaas run`` exits 1). Any other value
        raises ValueError naming it before anything starts (``aerodaas run``: exit 2, before Ray). While the
        application is loaded (``aerodaas run``), only marks the mission's start."""
        return _fly(self.env, [self], timeout, options)

    def end_mission(self, reason: str = "ended") -> None:
        """End the running mission now (the run stops; the result's outcome is ``reason``)."""
        if self._handle is not None:
            import ray  # lazy: heavy ray

            ray.get(self._handle.end_mission.remote(reason))

    def pause_mission(self) -> None:
        """Hover in place until :meth:`resume_mission`."""
        if self._handle is None:
            raise RuntimeError(f"robot {self.id!r}: no mission is running")
        import ray  # lazy: heavy ray

        ray.get(self._handle.pause_mission.remote())

    def resume_mission(self) -> None:
        if self._handle is None:
            raise RuntimeError(f"robot {self.id!r}: no mission is running")
        import ray  # lazy: heavy ray

        ray.get(self._handle.resume_mission.remote())

    # -- the camera gimbal (gimbal protocol v2 conventions: aerodaas.navigation.gimbal)
    def point_gimbal(self, pitch_deg: float, yaw_deg: float = 0.0) -> None:
        """Point the camera gimbal at ``pitch_deg`` (0 the horizon, -90 straight down) and ``yaw_deg`` (relative to
        the vehicle's nose, positive right), degrees, within the robot's ``gimbal`` limits. Before the mission
        starts the command is kept and carried out at take-off; while it runs it is sent now (through the drone's
        safety gate; the simulator's gimbal slews at ``rate_deg_s``, a MAVLink vehicle gets
        MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW). Raises :class:`~aerodaas.navigation.gimbal.GimbalError` naming the
        field and value (not finite, out of limits, no gimbal section) before anything is sent, and the backend's
        error when the vehicle refuses."""
        self._gimbal(GimbalPoint(pitch_deg, yaw_deg))

    def set_gimbal_roi(self, x: float, y: float, z: float = 0.0) -> None:
        """Keep the camera on the region of interest at (``x``, ``y``, ``z``) ENU metres from home (the simulator
        aims from the vehicle's pose at every step; a MAVLink vehicle gets MAV_CMD_DO_SET_ROI_LOCATION). Raises
        GimbalError as :meth:`point_gimbal`."""
        self._gimbal(GimbalRoi(x, y, z))

    def clear_gimbal_roi(self) -> None:
        """Stop following the region of interest (MAV_CMD_DO_SET_ROI_NONE); the gimbal stays where it points."""
        self._gimbal(GimbalRelease())

    def gimbal_attitude(self) -> dict | None:
        """The gimbal's latest attitude while the mission runs (``t`` vehicle s, ``q`` (w, x, y, z), ``pitch_deg``,
        ``yaw_deg``, ...: the ``aerodaas.GimbalAttitude`` record), None before the first report. Raises
        RuntimeError when no mission is running."""
        if self._handle is None:
            raise RuntimeError(f"robot {self.id!r}: no mission is running")
        import ray  # lazy: heavy ray

        return ray.get(self._handle.gimbal_attitude.remote())

    def _gimbal(self, cmd) -> None:
        """Check ``cmd`` against the robot's gimbal limits (GimbalError naming the field and value), then keep it
        for take-off or send it to the running drone (its error raised here, typed)."""
        lim = self.cfg.gimbal
        if lim is None:
            raise GimbalError(f"robot {self.id!r} has no gimbal: add a 'gimbal' section to its configuration "
                              f"(pitch_min_deg, pitch_max_deg, yaw_min_deg, yaw_max_deg, rate_deg_s)")
        try:
            if isinstance(cmd, GimbalPoint):
                lim.check(cmd.pitch_deg, cmd.yaw_deg)
            elif isinstance(cmd, GimbalRoi):
                lim.check_roi(cmd.x, cmd.y, cmd.z)
        except GimbalError as e:
            raise GimbalError(f"robot {self.id!r}: {e}", e.field, e.value) from None
        if self._handle is None:
            self.gimbal_commands.append(cmd)
            return
        import ray  # lazy: heavy ray

        try:
            ray.get(self._handle.point_gimbal.remote(cmd))
        except ray.exceptions.RayTaskError as e:
            cause = getattr(e, "cause", None)
            raise (cause if isinstance(cause, Exception) else e) from None

    def __repr__(self) -> str:
        return f"Robot({self.id!r}, backend={self.cfg.backend!r})"


class Environment:
    """IEnvironment, built from an ``environment.json``. A relative path is looked up in the working
    directory, then next to the application file. Raises :class:`aerodaas.config.ConfigError`. Never starts Ray."""

    def __init__(self, path: str | os.PathLike | EnvironmentConfig) -> None:
        if isinstance(path, EnvironmentConfig):
            cfg = path
        else:
            path = env_path_override() or path  # `aerodaas run --env FILE` while the application loads
            p = Path(path)
            if not p.is_absolute() and not p.exists():
                frame = inspect.currentframe()  # the caller's file, without inspect.stack()'s source reads (~60 ms)
                caller = Path(frame.f_back.f_code.co_filename if frame and frame.f_back else ".").resolve().parent
                if (caller / p).exists():
                    p = caller / p
            cfg = load_environment_config(p)
        self.cfg = cfg
        self.robots = {r.id: Robot(r, self) for r in cfg.robots}
        self.env_sensors = {s.id: Sensor(s) for s in cfg.env_sensors}
        self.compute = {c.id: ComputeResource(c) for c in cfg.compute}
        self._trajectory_scheduler = None
        self.hitl = None  # the running HitlServer (url, token) while a mission with the HITL API runs

    # -- sensors
    def has_env_sensors(self) -> bool:
        return bool(self.env_sensors)

    def get_env_sensors(self) -> list[Sensor]:
        return list(self.env_sensors.values())

    def get_env_sensor_by_id(self, sensor_id: str) -> Sensor:
        if sensor_id not in self.env_sensors:
            raise KeyError(f"no environment sensor {sensor_id!r}; known: {sorted(self.env_sensors)}")
        return self.env_sensors[sensor_id]

    def is_robot_sensor_available(self, sensor_type_or_id: str) -> bool:
        """True if some robot has a sensor with this id or type."""
        return any(s.id == sensor_type_or_id or s.type == sensor_type_or_id
                   for r in self.robots.values() for s in r.sensors.values())

    def get_robot_sensors(self) -> list[Sensor]:
        return [s for r in self.robots.values() for s in r.sensors.values()]

    # -- robots
    def get_env_robots(self) -> list[Robot]:
        return list(self.robots.values())

    def get_robot_by_id(self, robot_id: str) -> Robot:
        """Raises KeyError naming the unknown id and the known ones."""
        if robot_id not in self.robots:
            raise KeyError(f"unknown robot id {robot_id!r}; the environment has {sorted(self.robots)}")
        return self.robots[robot_id]

    # -- compute
    def get_compute_resources(self) -> list[ComputeResource]:
        return list(self.compute.values())

    def get_compute_resource_by_id(self, compute_id: str) -> ComputeResource:
        if compute_id not in self.compute:
            raise KeyError(f"unknown compute resource {compute_id!r}; the environment has {sorted(self.compute)}")
        return self.compute[compute_id]

    # -- the fleet
    def start_mission(self, robots: list["Robot"] | None = None, timeout: float | None = None, *,
                      options: Any = None):
        """Fly several robots together (default: every robot of the environment) on one clock; blocks and returns
        one MissionResult with a report per robot. Robots sharing the environment's trajectory scheduler each get
        their own waypoint queue holding the missions they were told to ``navigate``. ``robots`` holds Robots of
        this environment or their ids; ``options``: the run's :class:`~aerodaas.runtime.options.RunOptions`. Raises
        KeyError for an unknown id and ValueError naming the item for anything else, or a robot given twice, or a
        ``timeout`` outside (0, 1e7] wall seconds (as :meth:`Robot.start_mission`), before anything starts. While the application is loaded (``aerodaas run``), only marks the mission's start."""
        if isinstance(robots, (Robot, str)):
            robots = [robots]
        given = list(robots) if robots is not None else self.get_env_robots()
        robots = []
        for i, r in enumerate(given):
            if isinstance(r, str):
                r = self.get_robot_by_id(r)
            if not isinstance(r, Robot) or self.robots.get(r.id) is not r:
                raise ValueError(f"start_mission: robots[{i}] must be a Robot of this environment or its id "
                                 f"(one of {sorted(self.robots)}), got {r!r}")
            if r in robots:
                raise ValueError(f"start_mission: robots[{i}] ({r.id!r}) is given twice")
            robots.append(r)
        return _fly(self, robots, timeout, options)

    # -- schedulers
    def set_trajectory_scheduler(self, scheduler: Any) -> None:
        """Plug in the trajectory scheduler (an INavigate, e.g. NearestNeighborScheduler)."""
        self._trajectory_scheduler = scheduler

    def adopt_scheduler(self, scheduler: Any) -> None:
        """Use ``scheduler`` as the trajectory scheduler unless one is already set (a scheduler constructed with
        this environment, ``Scheduler(env)``, adopts itself; :meth:`set_trajectory_scheduler` always replaces)."""
        if self._trajectory_scheduler is None:
            self._trajectory_scheduler = scheduler

    def trajectory_scheduler(self) -> Any:
        """The trajectory scheduler: the one the app set, else ``environment.json``'s ``trajectory_scheduler``
        (a registered name or ``module.path:ClassName``, constructed as ``Class(env)``), else
        :class:`aerodaas.schedulers.TrajectoryScheduler`."""
        if self._trajectory_scheduler is None:
            cls = TrajectoryScheduler
            if self.cfg.trajectory_scheduler is not None:
                cls = registry.get("trajectory_scheduler", self.cfg.trajectory_scheduler)
            self._trajectory_scheduler = cls(self)
        return self._trajectory_scheduler

    def set_analytics_scheduler(self, name: str, models: dict | None = None, *, workload: str | None = None,
                                load: str | None = None, cloud_executors: int | None = None,
                                network: str | list[str] | None = None) -> None:
        """Plug in the analytics scheduler by name (the paper's setAnalyticsScheduler), as ``analytics_scheduler``
        in ``environment.json`` does; arguments given here replace the file's.

        ``name``: ``default`` (every analytics runs where it is deployed) or a registered scheduler (``DEMS``,
        ``DEMS-A``, ``GEMS``, ``E+C``, ``DEM``, ``CLOUD``, ``EDGE_EDF``, ..., ``GAINPLAN``). ``models``: analytics name
        -> QoS dict (``deadline_ms``, ``edge_ms``, ``cloud_ms``, ``benefit``, ``edge_cost``, ``cloud_cost``; ms and
        utility units) or a model name of ``workload`` under ``load``. Each frame reaching a named analytics then
        becomes a task the scheduler runs on the edge, sends to the cloud, or drops. See
        :class:`aerodaas.config.AnalyticsSchedulerConfig`. Raises ConfigError naming the bad field and value."""
        cur = self.cfg.analytics_scheduler.model_dump()
        cur["name"] = name
        for k, v in (("models", models), ("workload", workload), ("load", load),
                     ("cloud_executors", cloud_executors), ("network", network)):
            if v is not None:
                cur[k] = v
        if workload is not None:
            cur["workload"] = str(self.cfg.resolve_path(workload, "analytics_scheduler.workload"))
        try:
            cfg = AnalyticsSchedulerConfig.model_validate(cur)
        except ValidationError as e:
            raise ConfigError(_format_errors(e, "set_analytics_scheduler").replace("\n  ", "\n  analytics_scheduler.")) from None
        if cfg.name != "default":
            cfg.resolved_workload(self.cfg)
        self.cfg.analytics_scheduler = cfg

    @property
    def analytics_scheduler(self) -> str:
        """Name of the analytics scheduler in use (``default``: none)."""
        return self.cfg.analytics_scheduler.name

    # camelCase aliases for readers of the paper
    getRobotById = get_robot_by_id
    getComputeResourceById = get_compute_resource_by_id
    setTrajectoryScheduler = set_trajectory_scheduler
    setAnalyticsScheduler = set_analytics_scheduler
