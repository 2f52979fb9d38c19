"""The embedded flight model exposed as a MAVLink vehicle that behaves like ArduPilot Copter or PX4 multicopter.

Written from the MAVLink common message set (mavlink.io: heartbeat, command, mission and offboard protocols)
and the autopilots' documented behaviour, *not* from :mod:`aerodaas.backends.mavlink`, so it tests the backend's
assumptions. Mode numbers come from ArduPilot's ``ArduCopter/mode.h`` (``Mode::Number``) and PX4's
``src/modules/commander/px4_custom_mode.h``; result codes from PX4 ``Commander::handle_command`` (refusals are
``MAV_RESULT_TEMPORARILY_REJECTED``) and ArduPilot ``GCS_MAVLINK`` (refusals are ``MAV_RESULT_FAILED``).

What differs between the two flavours (all emulated):

* HEARTBEAT ``autopilot`` (ARDUPILOTMEGA 3 / PX4 12) and ``custom_mode`` (ArduCopter mode number / PX4
  ``main_mode << 16 | sub_mode << 24``).
* Take-off: ArduPilot needs GUIDED and armed, ``param7`` is metres above home; PX4 switches to AUTO.TAKEOFF and
  ``param7`` is metres above mean sea level (NaN: ``MIS_TAKEOFF_ALT`` above home), then holds (AUTO.LOITER).
* Position/velocity targets: ArduPilot honours them in GUIDED (velocity targets stop after 3 s without a new
  one); PX4 only in OFFBOARD, which it refuses to enter without a setpoint stream and leaves (to AUTO.LOITER)
  when the stream stops for ``COM_OF_LOSS_T`` seconds.
* Missions: ArduPilot keeps home at sequence 0 (uploads carry a placeholder there, downloads return home);
  PX4 numbers the first item 0. ArduPilot's AUTO on the ground needs a NAV_TAKEOFF first and starts on
  MAV_CMD_MISSION_START; PX4 takes off by itself and holds (AUTO.LOITER) when the mission ends.
* Streams: ArduPilot sends nothing but HEARTBEAT until asked (SET_MESSAGE_INTERVAL or the legacy
  REQUEST_DATA_STREAM); PX4 streams its default set and ignores REQUEST_DATA_STREAM.
* Before its GPS fix ArduPilot sends GLOBAL_POSITION_INT with latitude/longitude 0; PX4 sends none.
* RTL: climb to ``RTL_ALT`` (cm, ArduPilot) / ``RTL_RETURN_ALT`` (m, PX4) when lower, fly home, land, disarm.
* Both auto-disarm on the ground ``DISARM_DELAY`` / ``COM_DISARM_PRFLT`` seconds after arming without a
  take-off, and after landing.

Time: the emulator has its own clock (``time_boot_ms`` starts at a non-zero boot time); ``speedup`` K runs physics,
streams, timeouts and the clock K times faster than real time. Test hooks: :meth:`set_blackhole` (link loss), :meth:`drop_next` (single lost packets),
:meth:`set_prearm_failure`, ``message_interval=False`` (old firmware that answers SET_MESSAGE_INTERVAL with
UNSUPPORTED), ``ignore_commands`` (commands never acknowledged), ``ack_only_commands`` (acknowledged ACCEPTED but
not carried out), ``in_progress_commands`` (answered MAV_RESULT_IN_PROGRESS forever), :meth:`reject_next`
(one-off refusals such as MAV_RESULT_TEMPORARILY_REJECTED), ``mission_int=False`` (firmware that speaks only the
float MISSION_REQUEST / MISSION_ITEM forms of the mission protocol), :meth:`send_status_text` (STATUSTEXT,
chunked as MAVLink 2 does when longer than 50 characters) and :meth:`inject` (raw bytes or a message on the
link, e.g. corrupt packets), ArduPilot SITL's ``SIM_ENGINE_FAIL`` / ``SIM_ENGINE_MUL`` parameters (motors that lift
nothing: the vehicle does not climb). :attr:`setpoint_log` and :attr:`mode_log` record every position/velocity target
and mode change in vehicle time.
"""
from __future__ import annotations

import math
import threading
import time
from collections import deque
from typing import TYPE_CHECKING, Any, Callable, Literal

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.config import Limits, RobotConfig
from aerodaas.model.types import GeoPoint
from aerodaas.sim.vehicle import SimVehicle
from aerodaas.emulators.mavlink.arming import ArmingMixin
from aerodaas.emulators.mavlink.camera import CameraHost
from aerodaas.emulators.mavlink.commands import CommandMixin
from aerodaas.emulators.mavlink.constants import _PX4_DEFAULT_STREAMS
from aerodaas.emulators.mavlink.gimbal import EmulatedCamera, EmulatedGimbal
from aerodaas.emulators.mavlink.flavour import (AIRFRAME_MAX_SPEED, AP_PREARM_DISPLAY_PERIOD_S, ARDUPILOT_PARAMS,
                                               PX4_PARAMS, SPEED_PARAMS)
from aerodaas.emulators.mavlink.guided import GuidedMixin
from aerodaas.emulators.mavlink.link import EmulatorLink
from aerodaas.emulators.mavlink.mission import MissionMixin
from aerodaas.emulators.mavlink.mission_run import MissionRunMixin
from aerodaas.emulators.mavlink.modes import ModeMixin
from aerodaas.emulators.mavlink.params import EmulatedParams
from aerodaas.emulators.mavlink.signing import EmulatedSigning
from aerodaas.emulators.mavlink.telemetry import TelemetryMixin

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link
    from aerodaas.emulators.mavlink.mission import _Transfer

M = mavlink

__all__ = ["MavlinkVehicleEmulator"]


class MavlinkVehicleEmulator(CommandMixin, ModeMixin, ArmingMixin, GuidedMixin, MissionMixin,
                             MissionRunMixin, TelemetryMixin):
    """A simulated ArduPilot Copter or PX4 multicopter speaking MAVLink 2 over TCP (server) or UDP.

    ``autopilot``: ``"ardupilot"`` or ``"px4"``. ``robot``: battery, yaw rate, altitude and home from a
    :class:`~aerodaas.config.RobotConfig` (defaults when None) - *not* its speed limits: like the firmware, the
    vehicle flies at its own speed parameters until the ground station changes them; ``home`` overrides the home
    (WGS-84 degrees, metres AMSL). ``speedup``: vehicle time runs this many times faster than real time.
    ``params``: overrides of the emulated parameters, defaults and units as the firmware's
    (:data:`.flavour.ARDUPILOT_PARAMS`: ``WPNAV_SPEED`` cm/s ...; :data:`.flavour.PX4_PARAMS`: ``MPC_XY_CRUISE``
    m/s ...), also readable and settable with the parameter protocol. ``gps_lock_s``: vehicle seconds until the
    3-D fix (ArduPilot: "EKF3 IMU0 origin set", home); ``ekf_gps_s``: vehicle seconds after that until the EKF
    has a position estimate ("EKF3 IMU0 is using GPS"; PX4: XY_POSITION_CONTROL healthy) - arming in a mode that
    needs a position is refused until then. ``home_alt_drift_m``: bound of PX4's in-flight home-altitude
    correction (default 2 m for PX4, 0 for ArduPilot; ``seed`` makes it repeatable). ``deny_default_speed``:
    MAV_CMD_DO_CHANGE_SPEED with a speed <= 0 is DENIED (default: ArduCopter yes, PX4 no, as the firmware).
    ``message_interval``: False emulates firmware without MAV_CMD_SET_MESSAGE_INTERVAL (UNSUPPORTED).
    ``ignore_commands``: MAV_CMD numbers that are silently dropped (never acknowledged).
    ``ack_only_commands``: MAV_CMD numbers acknowledged MAV_RESULT_ACCEPTED but not carried out (a vehicle that
    says yes and does nothing: the HEARTBEAT never shows the new mode / armed state).
    ``in_progress_commands``: MAV_CMD numbers answered MAV_RESULT_IN_PROGRESS, repeated every 0.5 vehicle seconds,
    and never finished. ``mission_int``: None (default) asks for mission items as the firmware does (ArduPilot
    MISSION_REQUEST, PX4 MISSION_REQUEST_INT) and accepts either item form; True asks with MISSION_REQUEST_INT;
    False emulates older firmware that asks with MISSION_REQUEST and answers MISSION_REQUEST_INT with MISSION_ITEM
    (latitude/longitude as float degrees). ``signing_key``: MAVLink 2 signing on from the start with this 32-byte
    key (default: off until a SETUP_SIGNING sets a key; :mod:`.signing`).

    Use :meth:`start` (returns the bound address), :meth:`stop`, :meth:`snapshot` for the state.
    """

    def __init__(self, autopilot: Literal["ardupilot", "px4"] = "ardupilot", *, robot: RobotConfig | None = None,
                 home: GeoPoint | None = None, speedup: float = 1.0, system_id: int = 1, component_id: int = 1,
                 params: dict[str, float] | None = None, gps_lock_s: float = 2.0, physics_hz: float = 50.0,
                 message_interval: bool = True, ignore_commands: set[int] | None = None,
                 ack_only_commands: set[int] | None = None, in_progress_commands: set[int] | None = None,
                 mission_int: bool | None = None, ekf_gps_s: float = 1.0, home_alt_drift_m: float | None = None,
                 deny_default_speed: bool | None = None, estimate_speed_error_mps: float = 0.0,
                 land_detect_s: float = 0.0, seed: int = 0, signing_key: bytes | None = None) -> None:
        if autopilot not in ("ardupilot", "px4"):
            raise ValueError(f"autopilot must be 'ardupilot' or 'px4', got {autopilot!r}")
        if not (speedup > 0 and math.isfinite(speedup)):
            raise ValueError(f"speedup must be a positive number, got {speedup!r}")
        robot = robot or RobotConfig(id="mavlink_sim")
        self.autopilot = autopilot
        self.px4 = autopilot == "px4"
        self.speedup = float(speedup)
        self.system_id, self.component_id = system_id, component_id
        self.origin = home or robot.home  # EKF origin: the simulator's ENU frame
        # the airframe's envelope; the robot's own limits are the ground station's business (it must set the
        # vehicle's speed parameters, as with the real firmware)
        self.limits = Limits(max_speed=AIRFRAME_MAX_SPEED, max_vertical_speed=3.0, max_acceleration=3.0,
                             max_yaw_rate=robot.limits.max_yaw_rate, max_altitude=robot.limits.max_altitude)
        self.veh = SimVehicle(robot.id, self.origin, self.limits, robot.battery, robot.noise)
        self.physics_dt = 1.0 / physics_hz
        self.gps_lock_s = gps_lock_s
        self.message_interval_supported = message_interval
        self.ignore_commands = set(ignore_commands or ())
        self.ack_only_commands = set(ack_only_commands or ())
        self.in_progress_commands = set(in_progress_commands or ())
        self._init_emulated_firmware(ekf_gps_s, mission_int, home_alt_drift_m, seed, estimate_speed_error_mps,
                                     land_detect_s, deny_default_speed)
        self._init_params(system_id, params)
        #: MAVLink 2 signing (signing.py): every link's parser checks, every packet out is signed, once a key is set
        self.signing = EmulatedSigning(signing_key)
        self._init_links(system_id, component_id)
        #: the parameter protocol over :attr:`params` (params.py)
        self.param_table = EmulatedParams(self.params, autopilot, self._enc)
        self._init_state()
        self._apply_speed_params()
        #: the vehicle's gimbal (a servo mount, as ArduCopter's MNT1_TYPE 1; the robot's ``gimbal`` limits or
        #: ArduPilot's defaults): gimbal.py
        self.gimbal = EmulatedGimbal(robot.gimbal)
        #: the camera component on the vehicle's system (camera.py; none until :meth:`attach_camera`)
        self.camera_host = CameraHost(system_id, self._enc)

    def set_param(self, name: str, value: float) -> None:
        """Set an emulated parameter (see the class docstring). Raises KeyError for an unknown name."""
        with self._lock:
            if name not in self.params:
                raise KeyError(f"unknown {self.autopilot} parameter {name!r}")
            self._store_param(name, float(value))

    def _store_param(self, name: str, value: float) -> None:
        """Store parameter ``name`` (firmware units); a speed parameter changes the vehicle's speeds at once."""
        self.params[name] = value
        if name in SPEED_PARAMS:
            self._apply_speed_params()

    def _on_param_request_list(self, link: _Link, msg: Any) -> None:
        for out in self.param_table.list_reply():
            self._send(out, link)

    def _on_param_request_read(self, link: _Link, msg: Any) -> None:
        for out in self.param_table.read_reply(msg):
            self._send(out, link)

    def _on_param_set(self, link: _Link, msg: Any) -> None:
        got = self.param_table.decode_set(msg)
        if got is not None:
            self._store_param(*got)
            self._send(self.param_table.message(got[0]))  # to every link, as the firmware broadcasts it

    def attach_camera(self, camera: EmulatedCamera | None) -> None:
        """Put ``camera`` on the vehicle's system (None takes it away): its HEARTBEAT starts with the next one
        of the autopilot, and it answers requests addressed to its component id (:class:`.camera.CameraHost`)."""
        with self._lock:
            self.camera_host.attach(camera)

    @property
    def camera(self) -> EmulatedCamera | None:
        """The attached camera component (None: none)."""
        return self.camera_host.camera

    @property
    def camera_requests(self) -> list[tuple[int, int]]:
        """(command, component asked) of every request the attached camera answered."""
        return self.camera_host.requests

    def _init_emulated_firmware(self, ekf_gps_s: float, mission_int: bool | None, home_alt_drift_m: float | None,
                                seed: int, estimate_speed_error_mps: float, land_detect_s: float,
                                deny_default_speed: bool | None) -> None:
        """The firmware behaviours the emulator models (see :meth:`__init__`'s arguments). Raises ValueError naming
        the argument for a value out of range."""
        autopilot = self.autopilot
        if not (ekf_gps_s >= 0 and math.isfinite(ekf_gps_s)):
            raise ValueError(f"ekf_gps_s must be a finite number >= 0, got {ekf_gps_s!r}")
        #: vehicle seconds from the GPS fix until the EKF fuses GPS (a position estimate); the firmware takes
        #: ~20 s (ArduCopter SITL) - shorter here so that tests stay fast
        self.ekf_gps_s = float(ekf_gps_s)
        #: None: the flavour's mission request form (ArduPilot MISSION_REQUEST, PX4 MISSION_REQUEST_INT, as the
        #: firmware sends them); False: older firmware that speaks only the float forms
        self.mission_int = mission_int
        drift = (2.0 if autopilot == "px4" else 0.0) if home_alt_drift_m is None else float(home_alt_drift_m)
        if not (drift >= 0 and math.isfinite(drift)):
            raise ValueError(f"home_alt_drift_m must be a finite number >= 0, got {home_alt_drift_m!r}")
        #: bound (m) of PX4's in-flight home-altitude correction (COM_HOME_EN); 0 disables it
        self.home_alt_drift_m = drift
        self._rng = np.random.default_rng(seed)
        if not (estimate_speed_error_mps >= 0 and math.isfinite(estimate_speed_error_mps)):
            raise ValueError(f"estimate_speed_error_mps must be a finite number >= 0, got {estimate_speed_error_mps!r}")
        #: the estimator reports the horizontal speed this much (m/s) below the true one, which GPS_RAW_INT carries:
        #: an estimator that lets the vehicle fly faster than its limit (stock PX4 SIH: 0.5 m/s at the p99,
        #: aerodaas.backends.mavlink.speed_margin); the physics flies the true speed at the vehicle's limit + this
        self.estimate_speed_error_mps = float(estimate_speed_error_mps)
        if not (land_detect_s >= 0 and math.isfinite(land_detect_s)):
            raise ValueError(f"land_detect_s must be a finite number >= 0, got {land_detect_s!r}")
        #: PX4: vehicle seconds after touchdown during which an unforced disarm is denied ("Disarming denied: not
        #: landed": its land detector has not confirmed the landing yet, commander Commander::disarm)
        self.land_detect_s = float(land_detect_s)
        #: MAV_CMD_DO_CHANGE_SPEED with a speed <= 0 (-2 "default") is DENIED (None: as the flavour's firmware,
        #: ArduCopter denies, PX4 accepts)
        self.deny_default_speed = (not self.px4) if deny_default_speed is None else bool(deny_default_speed)

    def _init_params(self, system_id: int, params: dict[str, float] | None) -> None:
        """The flavour's parameters (with the system id) and the given overrides. Raises ValueError for an unknown
        parameter name."""
        autopilot = self.autopilot
        self._rejections: dict[int, list[int]] = {}  # MAV_CMD -> results still to answer (reject_next)
        self._in_progress: dict[int, tuple[_Link, int, int, float, int]] = {}  # cmd -> (link, sys, comp, next t, %)
        self.params: dict[str, float] = dict(PX4_PARAMS if self.px4 else ARDUPILOT_PARAMS)
        self.params["MAV_SYS_ID" if self.px4 else "SYSID_THISMAV"] = float(system_id)
        if self.px4:
            # PX4 SITL stretches its loss timeouts by the simulation's speed factor, so that they stay the same in
            # wall time (ROMFS init.d-posix/rcS, "Adapt timeout parameters if simulation runs faster or slower than
            # realtime": COM_OF_LOSS_T = PX4_SIM_SPEED_FACTOR x 1.0 s); at 10x the unscaled 1 s was 0.1 s of wall
            # time, less than a loaded machine stalls a setpoint stream for
            self.params["COM_OF_LOSS_T"] = self.speedup * PX4_PARAMS["COM_OF_LOSS_T"]
        for k, v in (params or {}).items():
            if k not in self.params:
                raise ValueError(f"params: unknown {autopilot} parameter {k!r}; known: {sorted(self.params)}")
            self.params[k] = float(v)

    def _init_links(self, system_id: int, component_id: int) -> None:
        """The MAVLink link (link.py: sockets, peers, faults), the vehicle thread and the pre-arm test hook."""
        #: the MAVLink link to the ground stations (link.py)
        self.link = EmulatorLink(system_id, component_id, self.signing)
        self._enc = self.link.enc
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.prearm_failure: str | None = None

    def _init_state(self) -> None:
        """The vehicle's state: clock, mode, home, targets, mission and fence items, message intervals."""
        # vehicle state
        self.t = 0.0
        self.boot_ms0 = 73_421  # the autopilot booted a while before we count
        self.mode = "MANUAL" if self.px4 else "STABILIZE"
        self.home: GeoPoint | None = None
        self.home_enu = np.zeros(3)
        self.armed_at = 0.0
        self.landed_at: float | None = None
        self.took_off = False
        self.speed: float | None = None  # DO_CHANGE_SPEED, m/s
        self.phase = ""  # RTL phase: climb / return / land
        self.last_setpoint_t = -1e9
        #: PX4: the mode its offboard-loss failsafe switched to, while the pilot's mode is still OFFBOARD (None: not
        #: in that failsafe); a setpoint stream that comes back ends it (modes.py)
        self.offboard_fallback: str | None = None
        #: vehicle time (s) of every position/velocity target received (the most recent 100 000)
        self.setpoint_log: deque[float] = deque(maxlen=100_000)
        #: (vehicle time s, mode name) of every mode change (the most recent 10 000)
        self.mode_log: deque[tuple[float, str]] = deque(maxlen=10_000)
        self.velocity_deadline: float | None = None  # ArduPilot GUIDED velocity timeout
        self._last_target: tuple | None = None  # last position/velocity target (PX4 acts on it in OFFBOARD)
        self.posvel: tuple | None = None  # active position + velocity feed-forward target (ENU m, m/s)
        self.takeoff_alt: float | None = None
        self.mission: list[Any] = []  # MISSION_ITEM_INT-like messages, wire sequence
        self.fence_items: list[Any] = []  # MAV_MISSION_TYPE_FENCE items (mission.py), as MISSION_ITEM_INT
        self.rally_items: list[Any] = []  # MAV_MISSION_TYPE_RALLY items
        self.mission_seq = 0
        self.mission_state = "idle"  # idle / wait_start / running / holding / done
        self.item_reached_at: float | None = None
        self.item_started = False
        self._item_target = np.zeros(3)  # ENU target of the mission item being flown
        self.reached_log: list[int] = []
        self._reached_repeat: tuple[int, int, float] | None = None  # PX4: (seq, repeats left, next vehicle s)
        self._mission_item_warned = False
        self._position_ok_sent = False
        self._next_prearm_report = AP_PREARM_DISPLAY_PERIOD_S
        self._home_corr = (0.0, 0.0, 0.0)  # PX4 home-altitude correction: (error m, applied m, next update s)
        self.took_off_at: float | None = None
        self._transfer: _Transfer | None = None
        # message id -> interval in vehicle seconds
        self._intervals: dict[int, float] = {m: 1.0 / hz for m, hz in _PX4_DEFAULT_STREAMS.items()} if self.px4 else {}
        self._next_due: dict[int, float] = {}
        self._next_hb = 0.0
        self.commands_seen: list[int] = []

    def start(self, address: str = "tcp:127.0.0.1:0", allow_remote: bool = False) -> str:
        """Listen (tcp, udpin) or send (udpout) on ``address`` and start the vehicle thread. Returns the address
        actually bound (port 0 -> the chosen port). Raises ValueError for a non-loopback address unless
        ``allow_remote``, OSError when the port cannot be bound."""
        bound = self.link.open(address, allow_remote)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"mavlink-{self.autopilot}-emulator", daemon=True)
        self._thread.start()
        return bound

    def stop(self) -> None:
        """Stop the vehicle thread and close every socket (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        self.link.close()

    def __enter__(self) -> "MavlinkVehicleEmulator":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    def _run(self) -> None:
        """The vehicle thread: read what the peers sent, handle it, run the physics and the firmware for the wall
        time elapsed x ``speedup`` (at most 0.5 s at a time: a stalled thread does not teleport the vehicle) in
        steps of ``physics_dt``, and push the output."""
        last = time.monotonic()
        while not self._stop.is_set():
            ready = self.link.wait(0.004)
            if ready is None:
                break
            with self._lock:
                for link, msg in self.link.receive(ready):
                    try:
                        self._handle(link, msg)
                    except Exception as e:  # noqa: BLE001 - report, keep flying
                        self._text(M.MAV_SEVERITY_ERROR, f"emulator: {msg.get_type()} handling failed: {e}")
                now = time.monotonic()
                elapsed = min(now - last, 0.5) * self.speedup
                last = now
                while elapsed > 1e-9:
                    dt = min(self.physics_dt, elapsed)
                    elapsed -= dt
                    self._tick(dt)
                self.link.flush()

    def _handlers(self) -> dict[str, Callable[[_Link, Any], None]]:
        """Message type -> the firmware's handler of it (a type not listed is ignored, e.g. HEARTBEAT)."""
        return {"COMMAND_LONG": self._on_command_long, "COMMAND_INT": self._on_command_int,
                "SET_MODE": self._on_set_mode, "REQUEST_DATA_STREAM": self._on_request_data_stream,
                "SET_POSITION_TARGET_GLOBAL_INT": self._on_set_position_target_global_int,
                "SET_POSITION_TARGET_LOCAL_NED": self._on_set_position_target_local_ned,
                "MISSION_COUNT": self._on_mission_count, "MISSION_ITEM_INT": self._on_mission_item_int,
                "MISSION_ITEM": self._on_mission_item, "MISSION_REQUEST_LIST": self._on_mission_request_list,
                "MISSION_REQUEST_INT": self._on_mission_request_int, "MISSION_REQUEST": self._on_mission_request,
                "MISSION_CLEAR_ALL": self._on_mission_clear_all, "MISSION_SET_CURRENT": self._on_mission_set_current,
                "PARAM_REQUEST_LIST": self._on_param_request_list, "PARAM_REQUEST_READ": self._on_param_request_read,
                "PARAM_SET": self._on_param_set}

    def _handle(self, link: _Link, msg: Any) -> None:
        """One message from ``link``: SETUP_SIGNING for this vehicle to the signing (signing.py), a message for
        another component to the camera (camera.py), the rest to its handler (:meth:`_handlers`)."""
        mtype = msg.get_type()
        if mtype == "SETUP_SIGNING":
            if self.link.for_us(msg):  # it passed this link's signature check (or signing is off)
                self.signing.on_setup_signing(msg)
            return
        handler = self._handlers().get(mtype)
        if handler is None:
            return
        if mtype != "REQUEST_DATA_STREAM" and not self.link.for_us(msg):
            boot_ms = int(self.boot_ms0 + self.t * 1000.0) & 0xFFFFFFFF
            self.camera_host.answer(link, msg, boot_ms)  # a camera component's, if one is attached (camera.py)
            return
        handler(link, msg)

    def _send(self, msg: Any, link: _Link | None = None) -> None:
        """Send ``msg`` to ``link`` (None: every peer): :meth:`.link.EmulatorLink.send`."""
        self.link.send(msg, link)

    def _text(self, severity: int, text: str) -> None:
        """STATUSTEXT ``text`` to every peer, chunked: :meth:`.link.EmulatorLink.text`."""
        self.link.text(severity, text)

    @property
    def _links(self) -> list[_Link]:
        """The connected peers (:attr:`.link.EmulatorLink.peers`)."""
        return self.link.peers

    def set_blackhole(self, on: bool, inbound: bool = True) -> None:
        """Drop everything the vehicle sends (and, with ``inbound``, everything it receives, logging its type and
        wall time in :attr:`blackholed_inbound`), like a radio out of range; the vehicle keeps flying on its own.
        ``False`` restores the link."""
        with self._lock:
            self.link.faults.set_blackhole(on, inbound)

    @property
    def blackholed(self) -> bool:
        """True while :meth:`set_blackhole` drops everything the vehicle sends (read without the lock: a link
        write racing a switch sends or drops that one message, as a radio at the edge of its range)."""
        return self.link.faults.blackhole

    def drop_next(self, msg_type: str, direction: Literal["in", "out"] = "out", count: int = 1) -> None:
        """Lose exactly the next ``count`` messages of type ``msg_type`` (e.g. ``"COMMAND_ACK"``,
        ``"MISSION_COUNT"``) that the vehicle sends (``"out"``) or receives (``"in"``), like single lost radio
        packets (a lost outgoing one used up its link's sequence number, as on a radio); each loss is logged in
        :attr:`dropped`. Raises ValueError for another direction or count < 1."""
        with self._lock:
            self.link.faults.drop_next(msg_type, direction, count)

    def inject(self, data: bytes | Any) -> None:
        """Put ``data`` on the link to every peer as if the vehicle had sent it: raw bytes (garbage, a corrupt
        frame) are written unchanged between two packets; a pymavlink message is packed with each link's
        sequence number."""
        with self._lock:
            self.link.inject(data)

    def send_status_text(self, text: str, severity: int = M.MAV_SEVERITY_INFO) -> None:
        """Send STATUSTEXT ``text`` (ASCII) to every peer; longer than 50 characters it goes out in chunks as
        MAVLink 2 specifies (same non-zero ``id``, ``chunk_seq`` from 0, the last chunk NUL-terminated)."""
        with self._lock:
            self._text(severity, text)

    @property
    def address(self) -> str | None:
        """The address :meth:`start` bound (None before)."""
        return self.link.address

    @property
    def dropped(self) -> list[tuple[str, str]]:
        """(direction "in"/"out", message type) of every message dropped by :meth:`drop_next`."""
        return self.link.faults.dropped

    @property
    def blackholed_inbound(self) -> list[tuple[float, str]]:
        """(wall monotonic s, message type) of every message that arrived while the inbound link was cut."""
        return self.link.faults.blackholed_inbound

    @property
    def statustexts(self) -> list[str]:
        """Every STATUSTEXT the vehicle sent, in full."""
        return self.link.statustexts

    @property
    def bad_packets(self) -> int:
        """Packets that did not parse."""
        return self.link.bad_packets

    def snapshot(self) -> dict[str, Any]:
        """The vehicle's state: ``t`` (vehicle seconds), ``mode``, ``armed``, ``in_air``, ``position`` (ENU metres
        from the *current* home), ``position_origin`` (ENU from the EKF origin), ``home`` (GeoPoint or None),
        ``gps_fix``, ``mission_seq``, ``mission_len`` (wire items), ``reached`` (MISSION_ITEM_REACHED seqs),
        ``links`` (connected peers), ``statustexts``, ``commands_seen``."""
        with self._lock:
            s = self.veh.state
            return {"t": self.t, "mode": self.mode, "armed": s.armed, "in_air": s.in_air,
                    "position": tuple(float(v) for v in s.position - self.home_enu),
                    "position_origin": tuple(float(v) for v in s.position), "home": self.home,
                    "gps_fix": self._fix_type(), "mission_seq": self.mission_seq, "mission_len": len(self.mission),
                    "reached": list(self.reached_log), "links": len(self.link.peers),
                    "statustexts": list(self.statustexts), "commands_seen": list(self.commands_seen),
                    "battery_pct": self.veh.battery_pct}

    def _motors_lift(self) -> bool:
        """Whether the motors can climb. ArduPilot SITL scales the PWM of the motors in ``SIM_ENGINE_FAIL`` (a
        bitmask, bit 0: servo 1) by ``SIM_ENGINE_MUL`` (libraries/SITL/SITL.cpp, SIM_Aircraft.cpp); the emulator
        models only whether its quad's four motors together give at least half their thrust (a quadrotor hovers near
        half throttle): below that it does not climb. PX4: always (SIH has no such parameter)."""
        if self.px4:
            return True
        mask, mul = int(self.params["SIM_ENGINE_FAIL"]), self.params["SIM_ENGINE_MUL"]
        return sum(mul if mask >> i & 1 else 1.0 for i in range(4)) / 4.0 >= 0.5

    def _tick(self, dt: float) -> None:
        self.t += dt
        veh, s = self.veh, self.veh.state
        if self.home is None and self._fix_type() >= 3:
            self._set_home_here()
            self._text(M.MAV_SEVERITY_INFO, "EKF3 IMU0 origin set" if not self.px4 else "home set")
        self._readiness_tick()
        was_in_air = s.in_air
        if s.armed:
            z0 = float(s.position[2])
            veh.step(dt)
            if s.position[2] > z0 and not self._motors_lift():  # full throttle, no climb
                s.position[2], s.velocity[2], s.in_air = z0, min(float(s.velocity[2]), 0.0), was_in_air
        if s.in_air:
            if not self.took_off:
                self.took_off_at = self.t
            self.took_off = True
        if was_in_air and not s.in_air:
            self.landed_at = self.t
        self._autopilot_logic()
        self.gimbal.step(dt, tuple(float(c) for c in s.position), float(s.yaw))
        self._stream()
