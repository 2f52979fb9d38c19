"""The MAVLink backend's pre-flight checks, run before Ray starts (:class:`~aerodaas.backends.mavlink.MavlinkBackend`
declares them as its ``check_config``, ``check_fleet`` and ``check_mission``): the autopilot's own geofence must
accept what the safety gate accepts, robots sharing one link must be told apart, and an autopilot mission must be
expressible as one. Each error names the field (``robots.<i>.mavlink.<field>``) and the value."""
from __future__ import annotations

from typing import Any

from aerodaas.backends.mavlink.signing import KeyFileError, TimestampStore, read_key_file
from aerodaas.config.base import ConfigError
from aerodaas.missionfile import MissionFileError, navigation_to_plan
from aerodaas.model.types import AeroNavigation, SchedulingType, Waypoint
from aerodaas.navigation.geofence import autopilot_disagreement

__all__ = ["check_autopilot_fence", "check_shared_links", "check_autopilot_mission", "resolve_signing_key"]


def check_autopilot_fence(robot: Any, where: str) -> None:
    """A robot whose MAVLink backend uploads its geofence (``mavlink.fence.upload``) must get an autopilot fence that
    accepts the same points as its safety gate. Checked here, before any actor starts, where the configuration
    alone decides it: a PX4 vehicle (``mavlink.autopilot: px4``) with two or more inclusion zones
    (:func:`aerodaas.navigation.geofence.autopilot_disagreement`), and a ``mavlink.fence.home_radius_m`` below
    ``safety.max_distance`` (both autopilots refuse a target beyond that circle, ArduPilot silently). A robot without
    a geofence leaves the vehicle's fence alone and is not checked. A vehicle identified on connect
    (``autopilot: auto``) is checked by the backend then, before it uploads anything.
    Raises ConfigError naming ``where`` (the robot's path) and the field."""
    mc = robot.backend_settings()
    if not mc.fence.upload or robot.safety.geofence.is_empty:
        return  # the backend leaves the vehicle's fence as it is
    radius = mc.fence.home_radius_m
    if radius is not None and radius < robot.safety.max_distance:
        raise ConfigError(f"{where}.mavlink.fence.home_radius_m: {radius:g} m is below safety.max_distance "
                          f"({robot.safety.max_distance:g} m): the autopilot would refuse targets beyond {radius:g} m "
                          f"from home that the safety gate accepts; set safety.max_distance to at most {radius:g} m")
    if mc.autopilot == "auto":
        return
    why = autopilot_disagreement(robot.safety.geofence, mc.autopilot)
    if why is not None:
        raise ConfigError(f"{where}.safety.geofence: robot {robot.id!r} uploads its geofence to a {mc.autopilot} "
                          f"vehicle (mavlink.fence.upload): {why}")


def resolve_signing_key(cls: Any, robot: Any, resolve: Any, where: str) -> None:
    """The MAVLink backend's ``resolve_files`` (``cls``: the backend class; ``where``: ``robots.<i>``):
    ``mavlink.signing_key_file`` resolved with ``resolve(path, field)``
    (the environment's :meth:`~aerodaas.config.EnvironmentConfig.resolve_path`) and written back absolute, then the
    key read (signing.py :func:`~aerodaas.backends.mavlink.signing.read_key_file`: a private file of 32 raw bytes or
    64 hex characters) and its timestamp file checked (:class:`~aerodaas.backends.mavlink.signing.TimestampStore`).
    Raises ConfigError naming ``field`` and the file (never the key)."""
    field = f"{where}.{cls.config_section}.signing_key_file"
    name = robot.backend_settings().signing_key_file
    if name is None:
        return
    path = str(resolve(name, field))
    try:
        read_key_file(path)
        TimestampStore(path).load()
    except (KeyFileError, OSError) as e:
        raise ConfigError(f"{field}: {name!r}: {e}") from None
    robot.backend_config["signing_key_file"] = path


def check_shared_links(robots: list[tuple[int, Any]]) -> None:
    """Robots whose ``mavlink.connection`` names one endpoint share one link (one socket, routed by system id;
    :mod:`aerodaas.backends.mavlink.shared_link`): each needs its own ``target_system``, one drone actor flies them
    all (so one edge compute), and they speak as one ground station (``source_system``, ``source_component``,
    ``baud`` alike). ``robots``: ``(index in robots[], RobotConfig)`` of every robot on a MAVLink backend. Raises
    ValueError naming both robots."""
    first: dict[str, tuple[int, Any, Any]] = {}
    ids: dict[tuple[str, int], Any] = {}
    for j, r in robots:
        mc = r.backend_settings()
        key = mc.link_key()
        if key not in first:
            first[key] = (j, r, mc)
        else:
            _, a, amc = first[key]
            for field in ("source_system", "source_component", "baud"):
                if getattr(amc, field) != getattr(mc, field):
                    raise ValueError(f"robots.{j}.mavlink.{field}: robots {a.id!r} and {r.id!r} share the link "
                                     f"{key} (one socket) but give {field} {getattr(amc, field)!r} and "
                                     f"{getattr(mc, field)!r}; a link speaks as one ground station")
            if a.compute != r.compute:
                raise ValueError(f"robots.{j}.compute: robots {a.id!r} and {r.id!r} share the link {key} (one socket, "
                                 f"so one drone actor) but name edge computes {a.compute!r} and {r.compute!r}")
        if isinstance(mc.target_system, int):
            if (key, mc.target_system) in ids:
                other = ids[(key, mc.target_system)]
                raise ValueError(f"robots.{j}.mavlink.target_system: robots {other.id!r} and {r.id!r} both fly "
                                 f"system id {mc.target_system} on the link {key}; each robot on one link needs its "
                                 f"own target_system (or 'auto')")
            ids[(key, mc.target_system)] = r


def check_autopilot_mission(robot: Any, sched: Any, hitl_on: bool) -> None:
    """``mavlink.use_autopilot_mission``: the robot's navigation must be a static, pre-planned waypoint list that
    an uploaded mission can express. Raises ConfigError naming the field and the reason: analytics navigating
    through the scheduler, the HITL API on (both add waypoints mid-flight), time-driven navigation, velocity
    commands or a land/rtl action before the end (MissionFileError), or no waypoints at all."""
    mc = robot.cfg.backend_settings()
    if not mc.use_autopilot_mission:
        return
    field = f"robots[{robot.id!r}].mavlink.use_autopilot_mission: true"
    if sched.stream_inputs:
        raise ConfigError(f"{field} flies a mission uploaded before take-off, but {len(sched.stream_inputs)} analytics "
                          "stream(s) navigate this robot through its trajectory scheduler (analytics-driven "
                          "navigation); set it to false to fly with position/velocity targets")
    if hitl_on:
        raise ConfigError(f"{field} flies a mission uploaded before take-off, but the human-in-the-loop API is on "
                          "(hitl.enabled / --hitl) and could add waypoints mid-flight; turn one of them off")
    timed = [m.name for m in sched.missions() if not m.distance_driven]
    if timed:
        raise ConfigError(f"{field}: navigation {timed} is time-driven; an autopilot mission holds only "
                          "distance-driven waypoints")
    items = sched.queued()
    if not any(isinstance(i, Waypoint) for i in items):
        raise ConfigError(f"{field}: robot {robot.id!r} has no pre-planned waypoints to upload "
                          "(call drone.navigate(...) before start_mission())")
    try:
        navigation_to_plan(AeroNavigation(waypoints=items, scheduling_type=SchedulingType.ORDERED), robot.cfg.home,
                           "land", takeoff_altitude=robot.cfg.takeoff_altitude)
    except MissionFileError as e:
        raise ConfigError(f"{field}: the navigation cannot be an autopilot mission: {e}") from None
