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

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.config import Limits, RobotConfig
from aerodaas.model.types import GeoPoint
from aerodaas.sim.vehicle import SimVehicle
from aerodaas.emulators.mavlink.arming import Arming
from aerodaas.emulators.mavlink.autopilot import AutopilotLoop
from aerodaas.emulators.mavlink.camera import CameraHost
from aerodaas.emulators.mavlink.commands import CommandHandler
from aerodaas.emulators.mavlink.flavour import AIRFRAME_MAX_SPEED
from aerodaas.emulators.mavlink.gimbal import EmulatedCamera, EmulatedGimbal
from aerodaas.emulators.mavlink.guided import GuidedTargets
from aerodaas.emulators.mavlink.link import EmulatorLink
from aerodaas.emulators.mavlink.mission import MissionProtocol
from aerodaas.emulators.mavlink.mission_run import MissionRunner
from aerodaas.emulators.mavlink.modes import FlightModes
from aerodaas.emulators.mavlink.motion import Motion
from aerodaas.emulators.mavlink.params import EmulatedParams, ParamProtocol
from aerodaas.emulators.mavlink.signing import EmulatedSigning
from aerodaas.emulators.mavlink.state import EmulatorState, MissionStore
from aerodaas.emulators.mavlink.telemetry import Telemetry

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link

M = mavlink

__all__ = ["MavlinkVehicleEmulator"]

#: a handler of one incoming message type: (the peer it came from, the parsed message)
Handler = Callable[["_Link", Any], None]


class MavlinkVehicleEmulator:
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

    Composed of one object per concern, each given the collaborators it uses: :attr:`state` (:mod:`.state`: flight
    model, clock, mode, home, targets) and :attr:`missions` (the stored items), :attr:`link` (:mod:`.link`),
    :attr:`telemetry`, :attr:`motion`, :attr:`arming`, :attr:`modes`, :attr:`guided`, :attr:`mission_protocol`,
    :attr:`mission_runner`, :attr:`commands`, :attr:`param_protocol`, :attr:`autopilot_loop`, :attr:`gimbal`,
    :attr:`camera_host`, :attr:`signing`. Incoming messages go through one table, message type -> bound handler
    (:attr:`handlers`).
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
        origin = home or robot.home  # EKF origin: the simulator's ENU frame
        # the airframe's envelope; the robot's own limits are the ground station's business (it must set the
        # vehicle's speed parameters, as with the real firmware)
        self.limits = Limits(max_speed=AIRFRAME_MAX_SPEED, max_vertical_speed=3.0, max_acceleration=3.0,
                             max_yaw_rate=robot.limits.max_yaw_rate, max_altitude=robot.limits.max_altitude)
        self.physics_dt = 1.0 / physics_hz
        #: the vehicle's state and settings (state.py)
        self.state = EmulatorState(
            autopilot, SimVehicle(robot.id, origin, self.limits, robot.battery, robot.noise), origin,
            system_id=system_id, speedup=self.speedup, params=params, gps_lock_s=gps_lock_s, ekf_gps_s=ekf_gps_s,
            estimate_speed_error_mps=estimate_speed_error_mps, land_detect_s=land_detect_s,
            home_alt_drift_m=home_alt_drift_m)
        #: the stored mission, fence and rally items and the mission run (state.py)
        self.missions = MissionStore(self.px4)
        #: MAVLink 2 signing (signing.py): every link's parser checks, every packet out is signed, once a key is set
        self.signing = EmulatedSigning(signing_key)
        #: the MAVLink link to the ground stations (link.py)
        self.link = EmulatorLink(system_id, component_id, self.signing)
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        #: the vehicle's gimbal (a servo mount, as ArduCopter's MNT1_TYPE 1; the robot's ``gimbal`` limits or
        #: ArduPilot's defaults): gimbal.py
        self.gimbal = EmulatedGimbal(robot.gimbal)
        #: the camera component on the vehicle's system (camera.py; none until :meth:`attach_camera`)
        self.camera_host = CameraHost(system_id, self.link.enc)
        self._compose(message_interval, mission_int, seed, ignore_commands, ack_only_commands, in_progress_commands,
                      deny_default_speed)
        self.motion.apply_speed_params()

    def _compose(self, message_interval: bool, mission_int: bool | None, seed: int, ignore_commands: set[int] | None,
                 ack_only_commands: set[int] | None, in_progress_commands: set[int] | None,
                 deny_default_speed: bool | None) -> None:
        """The concern objects, each given its collaborators, and the message table (see :meth:`__init__`'s
        arguments)."""
        st, store, link = self.state, self.missions, self.link
        self.telemetry = Telemetry(st, store, link, self.gimbal, self.camera_host, message_interval)
        self.motion = Motion(st)
        #: the parameter protocol over :attr:`params` (params.py)
        self.param_table = EmulatedParams(st.params, self.autopilot, link.enc)
        self.param_protocol = ParamProtocol(self.param_table, link, self.motion)
        self.arming = Arming(st, link, self.telemetry, seed)
        self.modes = FlightModes(st, store, link, self.motion)
        self.guided = GuidedTargets(st, self.modes, self.motion)
        self.mission_protocol = MissionProtocol(st, store, link, self.telemetry, mission_int)
        self.mission_runner = MissionRunner(st, store, link, self.modes, self.motion, self.arming,
                                            self.mission_protocol)
        self.commands = CommandHandler(st, link, self.telemetry, self.arming, self.modes, self.motion,
                                       self.mission_runner, self.mission_protocol, self.gimbal,
                                       ignore_commands=ignore_commands, ack_only_commands=ack_only_commands,
                                       in_progress_commands=in_progress_commands,
                                       deny_default_speed=deny_default_speed)
        self.autopilot_loop = AutopilotLoop(st, store, link, self.arming, self.modes, self.motion,
                                            self.mission_runner)
        cmd, mp, pp = self.commands, self.mission_protocol, self.param_protocol
        #: message type -> the firmware's handler of it (a type not listed is ignored, e.g. HEARTBEAT)
        self.handlers: dict[str, Handler] = {
            "COMMAND_LONG": cmd.on_command_long, "COMMAND_INT": cmd.on_command_int, "SET_MODE": cmd.on_set_mode,
            "REQUEST_DATA_STREAM": self.telemetry.on_request_data_stream,
            "SET_POSITION_TARGET_GLOBAL_INT": self.guided.on_set_position_target_global_int,
            "SET_POSITION_TARGET_LOCAL_NED": self.guided.on_set_position_target_local_ned,
            "MISSION_COUNT": mp.on_mission_count, "MISSION_ITEM_INT": mp.on_mission_item_int,
            "MISSION_ITEM": mp.on_mission_item, "MISSION_REQUEST_LIST": mp.on_mission_request_list,
            "MISSION_REQUEST_INT": mp.on_mission_request_int, "MISSION_REQUEST": mp.on_mission_request,
            "MISSION_CLEAR_ALL": mp.on_mission_clear_all, "MISSION_SET_CURRENT": mp.on_mission_set_current,
            "PARAM_REQUEST_LIST": pp.on_param_request_list, "PARAM_REQUEST_READ": pp.on_param_request_read,
            "PARAM_SET": pp.on_param_set}

    @property
    def params(self) -> dict[str, float]:
        """The emulated parameters (name -> value in the firmware's units; read-only by convention: change them
        with :meth:`set_param` or PARAM_SET)."""
        return self.state.params

    @property
    def mode_log(self) -> deque[tuple[float, str]]:
        """(vehicle time s, mode name) of every mode change (the most recent 10 000)."""
        return self.state.mode_log

    @property
    def setpoint_log(self) -> deque[float]:
        """Vehicle time (s) of every position/velocity target received (the most recent 100 000)."""
        return self.state.setpoint_log

    def set_param(self, name: str, value: float) -> None:
        """Set an emulated parameter (see the class docstring). Raises KeyError for an unknown name."""
        with self._lock:
            if name not in self.state.params:
                raise KeyError(f"unknown {self.autopilot} parameter {name!r}")
            self.param_protocol.store(name, float(value))

    def reject_next(self, command: int, count: int = 1, result: int = M.MAV_RESULT_TEMPORARILY_REJECTED) -> None:
        """Answer the next ``count`` COMMAND_LONG/COMMAND_INT ``command`` with ``result`` without carrying it out
        (:meth:`.commands.CommandHandler.reject_next`; raises ValueError as it does)."""
        with self._lock:
            self.commands.reject_next(command, count, result)

    def set_prearm_failure(self, text: str | None) -> None:
        """Make pre-arm checks fail with ``text`` (e.g. ``"Compass not calibrated"``); None clears it."""
        with self._lock:
            self.state.prearm_failure = text

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
                        self.link.text(M.MAV_SEVERITY_ERROR, f"emulator: {msg.get_type()} handling failed: {e}")
                now = time.monotonic()
                elapsed = min(now - last, 0.5) * self.speedup
                last = now
                while elapsed > 1e-9:
                    dt = min(self.physics_dt, elapsed)
                    elapsed -= dt
                    self._tick(dt)
                self.link.flush()

    def _handle(self, link: _Link, msg: Any) -> None:
        """One message from ``link``: SETUP_SIGNING for this vehicle to the signing (signing.py), a message for
        another component to the camera (camera.py), the rest to its handler (:attr:`handlers`)."""
        mtype = msg.get_type()
        if mtype == "SETUP_SIGNING":
            if self.link.for_us(msg):  # it passed this link's signature check (or signing is off)
                self.signing.on_setup_signing(msg)
            return
        handler = self.handlers.get(mtype)
        if handler is None:
            return
        if mtype != "REQUEST_DATA_STREAM" and not self.link.for_us(msg):
            self.camera_host.answer(link, msg, self.state.boot_ms())  # an attached camera's (camera.py)
            return
        handler(link, msg)

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
            self.link.text(severity, text)

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
        ``links`` (connected peers), ``statustexts``, ``commands_seen``, ``battery_pct``."""
        with self._lock:
            st = self.state
            s = st.veh.state
            return {"t": st.t, "mode": st.mode, "armed": s.armed, "in_air": s.in_air,
                    "position": tuple(float(v) for v in s.position - st.home_enu),
                    "position_origin": tuple(float(v) for v in s.position), "home": st.home,
                    "gps_fix": st.fix_type(), "mission_seq": self.missions.seq,
                    "mission_len": len(self.missions.mission), "reached": list(self.missions.reached_log),
                    "links": len(self.link.peers), "statustexts": list(self.statustexts),
                    "commands_seen": list(self.commands.seen), "battery_pct": st.veh.battery_pct}

    def _tick(self, dt: float) -> None:
        """One physics step of ``dt`` vehicle seconds: home at the GPS fix, readiness, the flight model (motors
        that lift nothing do not climb), take-off and landing, the autopilot's logic, the gimbal, then what is
        due on the link (HEARTBEAT, IN_PROGRESS answers, PX4's repeated MISSION_ITEM_REACHED, a stalled upload's
        request, the streams), in that order."""
        st = self.state
        st.t += dt
        veh, s = st.veh, st.veh.state
        if st.home is None and st.fix_type() >= 3:
            self.arming.set_home_here()
            self.link.text(M.MAV_SEVERITY_INFO, "EKF3 IMU0 origin set" if not self.px4 else "home set")
        self.arming.readiness_tick()
        was_in_air = s.in_air
        if s.armed:
            z0 = float(s.position[2])
            veh.step(dt)
            if s.position[2] > z0 and not st.motors_lift():  # full throttle, no climb
                s.position[2], s.velocity[2], s.in_air = z0, min(float(s.velocity[2]), 0.0), was_in_air
        if s.in_air:
            if not st.took_off:
                st.took_off_at = st.t
            st.took_off = True
        if was_in_air and not s.in_air:
            st.landed_at = st.t
        self.autopilot_loop.step()
        self.gimbal.step(dt, tuple(float(c) for c in s.position), float(s.yaw))
        self.telemetry.heartbeat_tick()
        self.commands.in_progress_tick()
        self.mission_runner.repeat_reached_tick()
        self.mission_protocol.transfer_tick()
        self.telemetry.interval_tick()
