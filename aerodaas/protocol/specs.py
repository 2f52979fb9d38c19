"""What one Ray actor of a run is built from: its part of the :class:`~aerodaas.runtime.dataflow.RunPlan`, typed.

The driver builds an :class:`ActorSpec` per actor (:func:`~aerodaas.runtime.dataflow.build_plan`), the run's
recorder actor keeps them (pickled with ``ray.cloudpickle``, so a restarted actor reads the same again) and
:class:`~aerodaas.actors.host.assembly.ActorAssembly` builds the actor's components from it. The specs hold the
application's own objects (analytics, trajectory schedulers, the analytics scheduler's class): they travel, not
their names.

* :class:`ActorSpec` — the actor's role, the simulation clock, the run's epoch, how it records, and its contents:
* :class:`RobotSpec` (one per drone of a drone actor, with its :class:`CameraSpec` s),
* :class:`AnalyticsSpec` (one per analytics instance in the actor),
* :class:`RecordSpec` (the recorder actor's file and live view),
* :class:`AnalyticsSchedulerSpec` (a dispatcher actor's analytics scheduler, set by the driver when it started the
  cloud executors).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

__all__ = ["Role", "CameraSpec", "RobotSpec", "AnalyticsSpec", "RecordSpec",
           "AnalyticsSchedulerSpec", "ActorSpec"]

#: what an actor of a run does (see :mod:`aerodaas.runtime.dataflow`)
Role = Literal["drone", "analytics", "dispatcher", "recorder"]


@dataclass(frozen=True)
class CameraSpec:
    """A camera of a drone: component id ``cid`` (``<robot>/<sensor>``), the sensor's id, its ``properties``
    from the robot's configuration (resolution in pixels, ``fps``, ``hfov_deg`` degrees, ``source``, ...) and
    ``source``, the :class:`aerodaas.plugins.frames.FrameSource` subclass its sensor class chose for them
    (``FrameSensor.frame_source``; None: the one ``properties.source`` names)."""

    cid: str
    sensor: str
    props: dict
    source: type | None = None


@dataclass
class RobotSpec:
    """One drone of a drone actor. ``robot``: its :class:`~aerodaas.config.RobotConfig` as a JSON dict;
    ``drone_cid``/``scheduler_cid``: the component ids of its drone and trajectory scheduler; ``scheduler``: the
    application's :class:`~aerodaas.schedulers.TrajectoryScheduler` object; ``preplanned``: how many waypoints its
    distance-driven missions hold at start; ``odom_cids``/``stat_cids``: its odometry and stat-stream sensors that
    have subscribers; ``plugin_sensors``: its plug-in sensors (:func:`aerodaas.plugins.sensor.sensor_plugin_spec`:
    component id, type, the plug-in class, its settings); ``plugins``: the plug-in classes its configuration names
    (:func:`aerodaas.plugins.registry.robot_plugins`), registered in the actor before the configuration is checked;
    ``gimbal``: the gimbal commands given before the mission started."""

    robot: dict
    drone_cid: str
    scheduler_cid: str
    scheduler: Any
    preplanned: int
    cameras: list[CameraSpec] = field(default_factory=list)
    odom_cids: list[str] = field(default_factory=list)
    stat_cids: list[str] = field(default_factory=list)
    plugin_sensors: list[dict] = field(default_factory=list)
    plugins: Any = None
    #: gimbal commands (:data:`aerodaas.protocol.gimbal.GimbalCommand`) the application gave before the mission
    #: started, carried out in order at take-off
    gimbal: list = field(default_factory=list)

    @property
    def robot_id(self) -> str:
        """The robot's id (``robots[].id``)."""
        return str(self.robot["id"])


@dataclass(frozen=True)
class AnalyticsSpec:
    """One analytics instance in an actor: component id ``cid``, the analytics' ``name``, the object itself
    (``obj``: an :class:`~aerodaas.analytics.core.Analytics`), how many items may wait for it (``buffer``) and
    whether its frames are placed on the edge or the cloud by the analytics scheduler (``scheduled``)."""

    cid: str
    name: str
    obj: Any
    buffer: int = 1
    scheduled: bool = False


@dataclass
class RecordSpec:
    """The run's recording: the MCAP file (absolute path, or None: live view only), the live view's
    ``HOST:PORT`` (or None), the file's metadata (str -> str), the plug-in sensors' message schemas (schema name ->
    JSON Schema), each drone's home (robot id -> ``HomeConfig`` dict: lat/lon of recorded tracks) and the track
    channels known from the plan (:func:`aerodaas.perception.track_records.declared_track_channels`), declared
    before the first message so the file and the live view have them from the start."""

    path: str | None
    live: str | None = None
    meta: dict[str, str] = field(default_factory=dict)
    schemas: dict[str, dict] = field(default_factory=dict)
    homes: dict[str, dict] | None = None
    declare: Any = None
    #: the live view's TLS files and token (:class:`aerodaas.clusters.tls.ServeAccess`; its repr hides the token)
    live_access: Any = None


@dataclass(frozen=True)
class AnalyticsSchedulerSpec:
    """A dispatcher actor's analytics scheduler: its ``name``, the :class:`~aerodaas.schedulers.analytics_base.
    AnalyticsScheduler` subclass itself (``policy_class``: resolved in the driver, where an application's own
    scheduler is registered), the ``workload`` (:class:`~aerodaas.schedulers.dispatch.workload.Workload`), the
    cloud executors' actor handles (may be empty), the emulated network's specs, the JPEG quality of frames sent
    to the cloud (1-100) and the random seed of the network emulation."""

    name: str
    policy_class: type
    workload: Any
    executors: list = field(default_factory=list)
    network: list[str] = field(default_factory=lambda: ["none"])
    jpeg_quality: int = 90
    seed: int = 0


@dataclass
class ActorSpec:
    """One actor's part of the plan. ``role``: what it does; ``sim``: the
    :class:`~aerodaas.config.SimulationConfig` as a dict; ``epoch_ns``: the run's time origin (ns since the Unix
    epoch; recorded log times are ``epoch_ns`` + simulated time); ``record``: the file and live view (the recorder
    actor only); ``record_remote``: the host id of the run's recorder actor, where this actor sends what it records
    (None: the run is not recorded); ``world``: the :class:`~aerodaas.config.WorldConfig` as a dict (drone actors:
    simulated cameras render it); ``robots``, ``analytics``: its drones and analytics instances;
    ``mavlink_links``: endpoint -> robot ids sharing one MAVLink socket in this actor; ``analytics_scheduler``: a
    dispatcher actor's scheduler (set by the driver); ``restart_hold_s``: in lock-step, how long a frame for a
    consumer actor that died waits for Ray to restart it (the environment's ``actor_restart_timeout_s``), seconds;
    ``opencv_threads``: OpenCV's worker threads in a drone or analytics actor (the environment's
    ``actor_opencv_threads``; None: OpenCV's default, one per core)."""

    role: Role
    sim: dict = field(default_factory=dict)
    epoch_ns: int = 0
    record: RecordSpec | None = None
    record_remote: str | None = None
    world: dict | None = None
    robots: list[RobotSpec] = field(default_factory=list)
    analytics: list[AnalyticsSpec] = field(default_factory=list)
    mavlink_links: dict[str, list[str]] = field(default_factory=dict)
    analytics_scheduler: AnalyticsSchedulerSpec | None = None
    restart_hold_s: float = 60.0
    opencv_threads: int | None = 1
