"""The vehicle-backend contract: what the runtime's drone component needs from a robot's driver.

One backend instance drives one robot. The runtime owns the flight logic (mission state machine, waypoint
acceptance, hover timers, safety gate, failsafes); a backend only *executes* commands and *reports* the
vehicle's state, so the same application flies the embedded simulator, an ArduPilot/PX4 autopilot over MAVLink,
a DJI Tello, or replays a recorded flight.

Conventions (as everywhere in AeroDaaS): positions are ENU metres relative to the robot's home (x east, y
north, z up), velocities ENU m/s, yaw in degrees counter-clockwise from east (ENU; MAVLink headings are
clockwise from north: ``yaw_enu = 90 - heading_ned``), times in seconds.

Clocks. ``clock == "sim"``: the vehicle only moves when :meth:`VehicleBackend.step` is called, by ``dt``
simulated seconds (the runtime's simulated clock: speedup and lock-step apply). ``clock == "vehicle"``: the
vehicle lives on its own clock (a real autopilot, an emulator, a log being replayed); :meth:`step` only
processes what has arrived since the last call and never blocks for long, and :attr:`t` is the vehicle's time
(e.g. from MAVLink ``time_boot_ms``, else wall time) in seconds since :meth:`connect` returned.

Errors. Every failure is a :class:`BackendError` subclass whose message names the robot and the command;
a refused command raises :class:`CommandRefused` carrying the autopilot's result code and its last status text.
"""
from __future__ import annotations

import abc
import dataclasses
import math
from typing import Any, Callable, ClassVar, NamedTuple, Protocol, Sequence, runtime_checkable

import numpy as np

from aerodaas.model.geo import enu_to_geodetic
from aerodaas.model.types import Attitude, GeoPoint, Odometry

__all__ = ["VehicleBackend", "VehicleState", "Actions", "Guidance", "Telemetry", "Gimbal", "Camera",
           "StateSamples", "BackendError", "CommandRefused", "LinkLost", "NotNavigable"]


def _vector3(name: str, value: Any) -> np.ndarray:
    """``value`` as a read-only (3,) float array; ValueError naming ``name`` and the value otherwise."""
    arr = np.array(value, dtype=float)
    if arr.shape != (3,):
        raise ValueError(f"VehicleState.{name}: expected 3 values, got {value!r}")
    arr.flags.writeable = False
    return arr


@dataclasses.dataclass(frozen=True, eq=False)
class VehicleState:
    """One reading of a vehicle's state, every field read together (what :meth:`VehicleBackend.state` returns).

    ``t``: seconds on the vehicle's clock when it was read (:attr:`VehicleBackend.t`); ``position``: (3,) float
    ENU metres from ``home`` (x east, y north, z up; ``home`` the ENU origin, WGS-84 degrees and metres, which a
    real vehicle may move: its HOME_POSITION); ``velocity``: (3,) float ENU m/s (both
    read-only arrays); ``roll``, ``pitch``, ``yaw``: attitude in degrees (yaw ENU: counter-clockwise from east,
    :meth:`VehicleBackend.enu_yaw_from_heading` converts a compass heading); ``battery_pct``: state of charge in
    percent, 0-100 (None: unknown, allowed for a backend with ``navigable = False``); ``armed``: the motors are
    armed, as the vehicle last reported it; ``in_air``: off the ground (the autopilot's land detector; always False
    for a vehicle with ``needs_takeoff = False``); ``link_ok``: False while the link is lost (no heartbeat or state
    for the configured time; always True in simulation); ``mode``: the vehicle's flight mode in its own names
    (MAVLink: pymavlink's ``GUIDED``, ``OFFBOARD``, ``LOITER``...; "" when it has none); ``position_accuracy_m``:
    the reported horizontal position accuracy, metres, 1 sigma as the receiver states it (0: exact or not
    reported).

    Raises ValueError naming the field when ``position`` or ``velocity`` is not 3 values."""

    t: float
    position: np.ndarray
    velocity: np.ndarray
    yaw: float
    armed: bool
    in_air: bool
    battery_pct: float | None
    home: GeoPoint
    roll: float = 0.0
    pitch: float = 0.0
    link_ok: bool = True
    mode: str = ""
    position_accuracy_m: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _vector3("position", self.position))
        object.__setattr__(self, "velocity", _vector3("velocity", self.velocity))


class PoseSample(NamedTuple):
    """One position sample of the vehicle and the run time it is of: ``t`` (s on the run's clock; for a vehicle on
    its own clock the sample's own time, e.g. GLOBAL_POSITION_INT ``time_boot_ms`` mapped to the run's clock, which
    can be up to one telemetry interval before :attr:`VehicleBackend.t`), ``position`` (3,) ENU metres from home,
    ``yaw_deg`` ENU degrees."""

    t: float
    position: tuple[float, float, float]
    yaw_deg: float


class BackendError(RuntimeError):
    """A vehicle backend failed (connection, protocol, timeout). The message names the robot and the step."""


class CredentialsRefused(BackendError):
    """The vehicle answers, but not to our credentials (a MAVLink signing key it does not hold): input the user must
    fix, not a fault of the link (``aerodaas run`` exits 2)."""


class RobotsNotConnected(BackendError):
    """Some robots of one drone actor could not connect to their vehicles: ``errors`` maps each such robot id to
    its own error (so the summary prints each robot's error under it, not the first one under all); ``refused``:
    the ids among them whose error was a :class:`CredentialsRefused`."""

    def __init__(self, errors: dict[str, str], refused: tuple[str, ...] = ()) -> None:
        self.errors = dict(errors)
        self.refused = tuple(refused)
        super().__init__("; ".join(self.errors.values()))

    def __reduce__(self):  # picklable across Ray workers
        return (RobotsNotConnected, (self.errors, self.refused))


class CommandRefused(BackendError):
    """The vehicle refused a command. ``result`` is the autopilot's code (e.g. the MAVLink ``MAV_RESULT`` name,
    or the Tello's ``error`` reply), ``status_text`` the last STATUSTEXT/log line that explains it."""

    def __init__(self, robot_id: str, command: str, result: str, status_text: str = "") -> None:
        self.robot_id, self.command, self.result, self.status_text = robot_id, command, result, status_text
        why = f" ({status_text})" if status_text else ""
        super().__init__(f"robot {robot_id!r}: {command} refused: {result}{why}")

    def __reduce__(self):  # picklable across Ray workers
        return (CommandRefused, (self.robot_id, self.command, self.result, self.status_text))


class LinkLost(BackendError):
    """A command could not be sent or confirmed because the link to the vehicle is lost."""


class NotNavigable(BackendError):
    """Navigation was asked of a backend that cannot navigate (e.g. the replay of a recorded flight)."""


# ---------------------------------------------------------------------- the command groups
# Every motion command below (takeoff, goto, set_velocity) has passed the robot's safety gate (geofence, altitude and
# speed limits) before it is called; a command returns once the vehicle accepted it, not once it is carried out (the
# drone watches the state).
@runtime_checkable
class Actions(Protocol):
    """Arming and take-off (:attr:`VehicleBackend.actions`)."""

    def arm(self) -> None:
        """Arm the motors (waiting until the vehicle is armable); called once, when the drone starts. Raises
        CommandRefused (the vehicle said no, e.g. a pre-arm check) or BackendError (no answer, the link): the run
        fails."""

    def disarm(self) -> None:
        """Disarm the motors. Called by the drone once the vehicle is on the ground (LANDED), or when it refuses the
        vehicle's home before a take-off. Raises CommandRefused when the vehicle refuses (e.g. still in the air)
        or BackendError; the drone records it and, at the end of the run, waits for the autopilot's own disarm."""

    def takeoff(self, altitude_m: float) -> None:
        """Climb to ``altitude_m`` metres above home; returns once the command is accepted (not reached). Never
        called when ``needs_takeoff`` is False. Raises CommandRefused / BackendError."""


@runtime_checkable
class Guidance(Protocol):
    """Where the vehicle goes (:attr:`VehicleBackend.guidance`)."""

    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        """Fly to ``target_enu`` (ENU metres from home, z up; a ground vehicle decides what z means to it) at up
        to ``speed`` m/s (None: the vehicle's limit). Replaces any previous target. Raises NotNavigable (a
        backend that only reports), CommandRefused or BackendError."""

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        """Hold the ENU velocity ``v_enu`` (3 values, m/s) and yaw rate (deg/s, counter-clockwise positive) until
        the next command. Raises NotNavigable, CommandRefused or BackendError."""

    def hold(self) -> None:
        """Hover (stop) where the vehicle is. Raises NotNavigable, CommandRefused or BackendError."""

    def land(self) -> None:
        """Descend and land where the vehicle is (a ground vehicle: stop). Raises NotNavigable, CommandRefused or
        BackendError; the drone then watches ``state().in_air`` for the touchdown (bounded by its landing
        deadline)."""

    def return_to_launch(self) -> bool:
        """Ask the vehicle to return home and land by itself. Returns False when it has no such mode (the drone
        then flies home with :meth:`goto` and lands with :meth:`land`)."""


@runtime_checkable
class Telemetry(Protocol):
    """The vehicle's position samples as the runtime records them (:attr:`VehicleBackend.telemetry`)."""

    def odometry(self) -> Odometry:
        """The current :class:`~aerodaas.model.types.Odometry` (its ``t``: the run time of the sample, at most
        :attr:`VehicleBackend.t`): ENU metres from home and their WGS-84 position, ENU m/s, attitude in degrees,
        battery percent, armed and in-air. Must not block."""

    def pose_sample(self) -> PoseSample:
        """The newest position and yaw with the run time they are of, read together (one sample, never the position
        of one and the time of another). A camera tags a frame with the pose interpolated between these samples at
        the frame's capture time, so the time must be the sample's, not the tick's that read it. Must not block."""

    @property
    def sample_key(self) -> Any:
        """None when every :meth:`odometry` is a fresh state (the simulator); otherwise a value that changes with
        each new position sample from the vehicle, so that the runtime records a sample once, never the same
        position again under a new timestamp."""

    def drain_odometry(self, newest_only: bool = False) -> list[Odometry]:
        """The vehicle's position samples not yet handed out, oldest first, each as an
        :class:`~aerodaas.model.types.Odometry` stamped with the vehicle's own time of the sample (``t``, seconds on
        the run's clock; ENU metres, m/s, degrees as in :meth:`odometry`). Raises nothing. A vehicle with a
        :attr:`sample_key` keeps every sample here until the runtime takes it, so a drone whose clock thread was
        held up (a command waiting for its acknowledgement, a loaded machine) still records each one.
        ``newest_only``: the newest sample alone; the others are discarded, not lost (the runtime was not recording
        them: before the run, or after the drone's mission ended)."""


@runtime_checkable
class Gimbal(Protocol):
    """A camera gimbal the drone can point (:attr:`VehicleBackend.gimbal`)."""

    def point(self, cmd: Any) -> None:
        """Carry out a gimbal command (:data:`aerodaas.protocol.gimbal.GimbalCommand`: pitch/yaw degrees, a region of
        interest in ENU metres, or its release), already checked against the robot's gimbal limits. Raises
        :class:`BackendError` when the vehicle refuses it."""

    def latest(self) -> Any:
        """The gimbal's latest attitude (:class:`aerodaas.protocol.gimbal.GimbalAttitude`, vehicle time), or None
        before the first report."""

    def drain(self) -> list:
        """Every gimbal attitude not handed out yet, oldest first (what the drone records on
        ``/<robot>/gimbal``)."""


@runtime_checkable
class Camera(Protocol):
    """The vehicle's own camera stream (:attr:`VehicleBackend.camera`)."""

    def frame(self) -> tuple[np.ndarray, float] | None:
        """The newest decoded frame, (H, W, 3) uint8 BGR, and its time on :attr:`VehicleBackend.t`'s clock; None
        when no frame arrived yet."""


class StateSamples:
    """The :class:`Telemetry` of a backend whose every :meth:`VehicleBackend.state` is a fresh sample (the
    simulator, or a vehicle that keeps no queue of its own): the default :attr:`VehicleBackend.telemetry`.

    ``backend``: the backend whose state is sampled; ``odometry``: a function returning the current
    :class:`~aerodaas.model.types.Odometry` when the backend makes its own (the simulator adds its GPS noise, a
    replayed log its own fix and voltage); None: from ``backend.state()``, its WGS-84 position from the state's
    ``home`` (:func:`aerodaas.model.geo.enu_to_geodetic`), battery clipped to 0-100 %."""

    sample_key = None

    def __init__(self, backend: "VehicleBackend", odometry: Callable[[], Odometry] | None = None) -> None:
        self._backend, self._odometry = backend, odometry

    def odometry(self) -> Odometry:
        """See :meth:`Telemetry.odometry`: the state now."""
        if self._odometry is not None:
            return self._odometry()
        s = self._backend.state()
        x, y, z = (float(v) for v in s.position)
        bat = None if s.battery_pct is None else min(max(float(s.battery_pct), 0.0), 100.0)
        return Odometry(robot_id=self._backend.robot_id, t=float(s.t), position=(x, y, z),
                        geodetic=enu_to_geodetic(x, y, z, s.home), velocity=tuple(float(v) for v in s.velocity),
                        attitude=Attitude(roll=s.roll, pitch=s.pitch, yaw=s.yaw), battery_pct=bat,
                        armed=bool(s.armed), in_air=bool(s.in_air))

    def odometry_json(self) -> dict:
        """:meth:`odometry` as ``model_dump(mode="json")`` gives it: what the drone records and publishes (a backend
        that can build the dict without the model's validation overrides this, with the same result)."""
        return self.odometry().model_dump(mode="json")

    def pose_sample(self) -> PoseSample:
        """See :meth:`Telemetry.pose_sample`: the state's position and yaw at its time (right for a backend whose
        state is new at every :meth:`VehicleBackend.step`)."""
        s = self._backend.state()
        p = s.position
        return PoseSample(float(s.t), (float(p[0]), float(p[1]), float(p[2])), float(s.yaw))

    def drain_odometry(self, newest_only: bool = False) -> list[Odometry]:
        """See :meth:`Telemetry.drain_odometry`: ``[self.odometry()]`` (each state is a new sample)."""
        return [self.odometry()]


class VehicleBackend(abc.ABC):
    """Driver of one robot. Subclasses set :attr:`kind`, :attr:`clock` and implement the abstract methods (the
    members docs/extending-vehicles.md "Writing a vehicle backend from scratch" tables, with units, frames, return
    types, errors and which are optional; ``examples/plugins/aerodaas_example_plugins/rover.py`` is a complete one).

    Construction: the drone actor builds the backend as ``Backend(cfg)`` with the robot's validated
    :class:`aerodaas.config.RobotConfig` (:func:`aerodaas.backends.make_backend`, called in
    ``actors/drone/component.py``); a subclass's ``__init__(self, cfg)`` calls this class's ``__init__(cfg.id, cfg.home)``
    and reads its settings with :meth:`options`. It must not open a link there (:meth:`connect` does).

    Errors: a command the vehicle refuses or cannot carry out raises a :class:`BackendError` (a
    :class:`CommandRefused`, :class:`LinkLost`, :class:`NotNavigable`): during the mission the drone records it as
    a ``backend_error`` event and the run goes on, and any other exception from a command ends the robot's mission
    as ``failed``; an exception from ``actions.arm()`` (the drone's start) or :meth:`step` ends the drone actor's
    run.

    Commands: the subclass's ``__init__`` sets two typed attributes, the command groups the drone calls directly:
    :attr:`actions` (:class:`Actions`: arm, disarm, take-off) and :attr:`guidance` (:class:`Guidance`: goto,
    set_velocity, hold, land, return_to_launch), each the concern object that carries the commands out (the same
    object may be both, or the backend itself); :func:`aerodaas.backends.make_backend` checks them.

    State: :meth:`state` returns one :class:`VehicleState` (position, velocity, attitude, battery, armed, in-air,
    link health, flight mode, position accuracy, all read together, with their time): a backend implements that
    one method, not a property per field.

    Samples: :attr:`telemetry` (:class:`Telemetry`: ``odometry()``, ``pose_sample()``, ``sample_key``,
    ``drain_odometry()``) is what the runtime records; the default :class:`StateSamples` takes each state as a
    sample, a vehicle that streams its own samples sets its own (the MAVLink backend's telemetry concern).

    Thread-safety: the runtime calls every method from one thread (the drone's control thread), except
    :meth:`state`, :attr:`t` and ``telemetry.odometry()``, which may also be read from a status thread and must
    not block.
    """

    #: the ``backend`` name in ``environment.json``
    kind: ClassVar[str] = ""
    #: "sim" (moves only in :meth:`step`) or "vehicle" (lives on its own clock)
    clock: ClassVar[str] = "vehicle"
    #: False for backends that only report (replay): navigation raises :class:`NotNavigable`
    navigable: ClassVar[bool] = True
    #: False for a vehicle that never leaves the ground (a rover, a boat): the drone arms it and goes straight to
    #: HOVERING (ready, nothing to do), without a take-off command or a take-off phase and its deadline
    #: (``robots[].deadlines``); its ``in_air`` stays False, so a landing ends at once
    needs_takeoff: ClassVar[bool] = True
    #: plug-in declaration (:mod:`aerodaas.plugins.registry`): a backend plug-in is one module with one subclass
    #: of this class (or of a built-in backend such as :class:`aerodaas.backends.sim.SimBackend`), constructed as
    #: ``Backend(cfg)`` with the robot's :class:`aerodaas.config.RobotConfig` (its ``__init__(cfg)`` calls this
    #: class's ``__init__(cfg.id, cfg.home)``); ``Config`` is the pydantic model of
    #: its own settings (``robots[].backend_config``, validated before Ray starts; read them with
    #: :meth:`options`); it produces the vehicle state (odometry, battery, events) and consumes flight commands
    plugin_kind: ClassVar[str] = "backend"
    Config: ClassVar[Any] = None
    #: a settings section named after the backend, accepted as an alias of ``backend_config`` (the built-ins'
    #: ``mavlink``, ``tello``, ``replay`` sections of existing environment files); None: ``backend_config`` only
    config_section: ClassVar[str | None] = None
    produces: ClassVar[tuple] = ("odometry", "events")
    consumes: ClassVar[tuple] = ("flight_commands",)
    #: whether the vehicle has its own camera stream (:attr:`camera`): a camera sensor with
    #: ``"source": "backend"`` needs one (checked when the environment is validated, before Ray starts)
    provides_camera: ClassVar[bool] = False
    #: whether the vehicle has a camera gimbal the drone can point (:attr:`gimbal`):
    #: a robot's ``gimbal`` section needs one (checked when the environment is validated, before Ray starts)
    provides_gimbal: ClassVar[bool] = False

    #: arming and take-off (:class:`Actions`), set by the subclass's ``__init__``
    actions: Actions
    #: where the vehicle goes (:class:`Guidance`), set by the subclass's ``__init__``
    guidance: Guidance
    #: the camera gimbal the drone points (:class:`Gimbal`), None: the vehicle has none (``provides_gimbal``
    #: declares that it may have one; a robot's ``gimbal`` section then needs it)
    gimbal: Gimbal | None = None
    #: the vehicle's own camera stream (:class:`Camera`, with ``provides_camera``), None: it has none (the Tello's
    #: video; a camera sensor with ``"source": "backend"`` reads it)
    camera: Camera | None = None

    # ------------------------------------------------------------------ what the drone asks of a backend
    @property
    def flies_uploaded_mission(self) -> bool:
        """Whether the robot's pre-planned waypoints are flown as a mission uploaded to the vehicle, which then
        flies it by itself (the backend then has a ``mission`` attribute with ``upload(nav, takeoff_altitude=,
        final_action=)`` returning :class:`aerodaas.missionfile.MissionItem` s and ``start()``, and reports
        ``mission_current`` / ``mission_item_reached`` events). False here."""
        return False

    @property
    def failsafe_action(self) -> str:
        """What the drone does after the vehicle entered a failsafe mode by itself (an ``autopilot_failsafe``
        event): ``"end"`` (the vehicle's own RTL/LAND flies on; the default), ``"hold"`` (paused until an operator
        resumes) or ``"resume"`` (the current waypoint is re-issued)."""
        return "end"

    @property
    def connects_first(self) -> bool:
        """Whether this robot connects before the run's others: it claims a fixed vehicle identity on a link it
        may share (a configured MAVLink system id) before robots that take the lowest one left. False here."""
        return False

    @classmethod
    def options(cls, cfg: Any) -> Any:
        """The robot's ``backend_config`` validated against ``Config`` (None when the class declares none).
        Raises pydantic's ValidationError."""
        if cls.Config is None:
            return None
        return cls.Config.model_validate(getattr(cfg, "backend_config", None) or {})

    # ------------------------------------------------------------------ pre-flight checks (before Ray starts)
    # Each takes robots' configurations (aerodaas.config.RobotConfig); the framework calls them for every robot
    # on this backend, whatever its name. Errors are aerodaas.config.ConfigError (or ValueError inside the
    # environment's validation) naming the field and the value.
    @classmethod
    def check_config(cls, robot: Any, where: str) -> None:
        """Checks of one robot's configuration that only this backend knows (``where``: ``robots.<i>``), once its
        files are resolved. Nothing here."""

    @classmethod
    def check_fleet(cls, robots: list[tuple[int, Any]]) -> None:
        """Checks across the environment's robots on this backend, ``(index in robots[], RobotConfig)``. Raises
        ValueError naming ``robots.<i>.<field>``. Nothing here."""

    @classmethod
    def resolve_files(cls, robot: Any, resolve: Any, where: str) -> None:
        """Resolve the files the robot's settings name, in place in ``robot.backend_config`` (``resolve(path,
        field)`` returns the absolute path or raises ConfigError naming ``field``). Nothing here."""

    @classmethod
    def link_key(cls, robot: Any) -> str | None:
        """The endpoint of a link several robots may share (one process must then hold it: their drone actor is
        one), or None: the robot has a link of its own. None here."""
        return None

    @classmethod
    def clock_rate(cls, robot: Any) -> float | None:
        """Vehicle seconds per wall second when the configuration sets it (a replayed log's ``rate``): a run on
        such backends only runs its clock at the fastest of them. None here (the run's ``speedup`` applies)."""
        return None

    @classmethod
    def check_mission(cls, robot: Any, sched: Any, hitl_on: bool) -> None:
        """Checks of the robot's queued navigation (``robot``: the application's :class:`aerodaas.app.api.Robot`,
        ``sched`` its trajectory scheduler) that only this backend knows, before any actor starts. Nothing here."""

    def __init__(self, robot_id: str, home: GeoPoint | None) -> None:
        """Sets :attr:`robot_id` (``robots[].id``), :attr:`home` (the ENU origin, WGS-84 degrees and metres; None:
        the vehicle keeps its own, reported in its :meth:`state`, and the backend has no ``home`` attribute) and the
        default :attr:`telemetry` (:class:`StateSamples`). Called by a subclass's ``__init__(cfg)`` as
        ``super().__init__(cfg.id, cfg.home)``, before it sets its own groups; raises nothing."""
        self.robot_id = robot_id
        if home is not None:
            #: the ENU origin (a replayed log may move it to its HOME_POSITION)
            self.home = home
        #: the position samples the runtime records (:class:`Telemetry`); a subclass may set its own
        self.telemetry: Telemetry = StateSamples(self)

    # ------------------------------------------------------------------ lifecycle
    def connect(self, timeout_s: float = 30.0) -> None:
        """Open the link and wait until the vehicle reports its state. Raises :class:`BackendError` after
        ``timeout_s`` seconds. The simulator is always connected."""

    def close(self) -> None:
        """Release the link (idempotent). Never raises."""

    def checkpoint(self) -> Any:
        """The vehicle state a restarted drone actor needs to go on (picklable), or None when the vehicle keeps its
        own state (a real vehicle flies on under its own control while the actor restarts): the default."""
        return None

    def restore(self, state: Any) -> None:
        """Take back a :meth:`checkpoint` (called after :meth:`connect` of a restarted drone actor)."""

    # ------------------------------------------------------------------ time and state
    @abc.abstractmethod
    def state(self) -> VehicleState:
        """The vehicle's state now, every field read together (:class:`VehicleState`: ENU metres from its home, the
        home, ENU m/s, degrees, battery percent, armed, in-air, link health, flight mode, position accuracy, and the
        time it was read on the vehicle's clock). Must not block; raises nothing."""

    @property
    def t(self) -> float:
        """Seconds on the vehicle's clock since :meth:`connect` (simulated seconds for the simulator); never goes
        back: ``state().t``. Must not block."""
        return self.state().t

    @abc.abstractmethod
    def step(self, dt: float) -> None:
        """Called once per physics step of the run (``dt`` = 1 / ``simulation.physics_hz`` seconds). ``clock ==
        "sim"``: advance the vehicle ``dt`` simulated seconds. ``"vehicle"``: process incoming messages
        (non-blocking; ``dt`` is only a hint). Should not raise: an exception leaves the drone actor's run loop (the
        run fails); report trouble as events (:meth:`drain_events`) or through ``state().link_ok``."""

    def drain_events(self) -> list[dict[str, Any]]:
        """Events since the last call, oldest first, each ``{"event": name, ...}``: e.g. ``status_text``
        (severity, text), ``mission_item_reached`` (seq), ``mode`` (name), ``link_lost``, ``link_regained``.
        The runtime records them on ``/<robot>/events``."""
        return []

    # ------------------------------------------------------------------ helpers for subclasses
    @staticmethod
    def enu_yaw_from_heading(heading_deg: float) -> float:
        """ENU yaw (deg, CCW from east) from a compass heading (deg, CW from north), in [0, 360)."""
        return (90.0 - heading_deg) % 360.0

    @staticmethod
    def heading_from_enu_yaw(yaw_deg: float) -> float:
        """Compass heading (deg, CW from north) from an ENU yaw, in [0, 360)."""
        return (90.0 - yaw_deg) % 360.0

    @staticmethod
    def ned_to_enu(v: Sequence[float]) -> np.ndarray:
        """(3,) NED vector -> ENU (swap north/east, negate down)."""
        return np.array([float(v[1]), float(v[0]), -float(v[2])])

    @staticmethod
    def enu_to_ned(v: Sequence[float]) -> np.ndarray:
        """(3,) ENU vector -> NED."""
        return np.array([float(v[1]), float(v[0]), -float(v[2])])

    def horizontal_distance(self, target_enu: Sequence[float]) -> float:
        """Metres from the vehicle to ``target_enu`` in the horizontal plane."""
        p = self.state().position
        return math.hypot(float(target_enu[0]) - p[0], float(target_enu[1]) - p[1])
