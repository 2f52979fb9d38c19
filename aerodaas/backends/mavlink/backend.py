"""The MAVLink vehicle backend: one class holding the concern objects (commands, parameters, mission transfers, mission,
actions, offboard, speed limits, telemetry, fence, gimbal, link, clock, status texts; see the package docstring)."""
from __future__ import annotations

import math
import threading
import time
from collections import deque
from typing import Any, Literal, Sequence

import numpy as np

from aerodaas.config import MavlinkConfig
from aerodaas.missionfile import MissionItem, MissionPlan
from aerodaas.model.types import GeoPoint, Odometry
from aerodaas.backends.base import BackendError, PoseSample, VehicleBackend
from aerodaas.backends.mavlink.action import Readiness, VehicleAction
from aerodaas.backends.mavlink.camera import CameraFinder
from aerodaas.backends.mavlink.clock import VehicleClock
from aerodaas.backends.mavlink.command import CommandProtocol
from aerodaas.backends.mavlink.fence import AutopilotFence
from aerodaas.backends.mavlink.gimbal import GimbalConcern
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink.mission import AutopilotMission
from aerodaas.backends.mavlink.offboard import OffboardControl
from aerodaas.backends.mavlink.params import ParameterProtocol, SpeedLimits
from aerodaas.backends.mavlink.preflight import resolve_signing_key
from aerodaas.backends.mavlink.signing import make_signing
from aerodaas.backends.mavlink.statustext import StatusTexts
from aerodaas.backends.mavlink.telemetry import Handler, VehicleTelemetry
from aerodaas.backends.mavlink.transfer import MissionTransfer, Wire
from aerodaas.navigation.geofence import GeofenceConfig
from aerodaas.backends.mavlink._common import M, _enum_name, _f32, _log_level, log  # noqa: F401


class MavlinkBackend(VehicleBackend):
    """An ArduPilot Copter or PX4 multicopter reached over MAVLink (settings: :class:`~aerodaas.config.MavlinkConfig`).

    ``clock == "vehicle"``: :attr:`t` is the autopilot's ``time_boot_ms`` (seconds since :meth:`connect`), wall time
    until a timestamped message arrives; while the link is lost it runs on from the last sample at the measured
    vehicle/wall rate (so the runtime's control ticks, and its LINK_LOST state, go on). Positions are ENU metres from the vehicle's HOME_POSITION (the configured
    home until the vehicle reports one). Besides the :class:`VehicleBackend` contract it offers
    :meth:`upload_mission`, :meth:`download_mission`, :meth:`start_mission`, :meth:`clear_mission`,
    :meth:`set_mode`, :meth:`apply_fence` / :meth:`upload_rally` / :meth:`restore_fence` (the vehicle's own geofence,
made the robot's ``safety.geofence`` on connect when ``mavlink.fence.upload``) and the attributes :attr:`autopilot` (``"ardupilot"``/``"px4"``), :attr:`mode`,
    :attr:`gps_fix_type`, :attr:`command_rtt_ms` (acknowledged command round trips, wall milliseconds).
    Every STATUSTEXT becomes a ``status_text`` event and a log line on the ``aerodaas.mavlink`` logger
    (``"<robot>: <text>"``; MAV_SEVERITY EMERGENCY-CRITICAL -> CRITICAL, ERROR, WARNING, NOTICE/INFO -> INFO,
    DEBUG).

    Raises :class:`BackendError` (connection, protocol timeouts), :class:`CommandRefused` (MAV_RESULT /
    MAV_MISSION_RESULT name and the autopilot's latest STATUSTEXT), :class:`CommandNotConfirmed` (a mode change or
    arming acknowledged but never shown by the HEARTBEAT) and :class:`LinkLost` (no HEARTBEAT for
    ``heartbeat_timeout_s``: commands fail at once instead of blocking).
    """

    kind = "mavlink"
    clock = "vehicle"
    #: a camera with ``source: "mavlink"`` reads the stream the vehicle announces (:meth:`discover_video_stream`)
    discovers_video_streams = True
    Config = MavlinkConfig
    config_section = "mavlink"
    provides_gimbal = True  # gimbal protocol v2 through the autopilot's gimbal manager (gimbal.py GimbalConcern)

    # the pre-flight checks of its settings (aerodaas.backends.mavlink.preflight), run before Ray starts
    @classmethod
    def check_config(cls, robot: Any, where: str) -> None:
        """The autopilot's own fence must accept what the safety gate accepts (``mavlink.fence``)."""
        from aerodaas.backends.mavlink.preflight import check_autopilot_fence

        check_autopilot_fence(robot, where)

    #: ``mavlink.signing_key_file`` resolved and checked before Ray starts (preflight.py)
    resolve_files = classmethod(resolve_signing_key)

    @classmethod
    def check_fleet(cls, robots: list[tuple[int, Any]]) -> None:
        """Robots on one link (``mavlink.connection``) speak as one ground station to distinct system ids."""
        from aerodaas.backends.mavlink.preflight import check_shared_links

        check_shared_links(robots)

    @classmethod
    def link_key(cls, robot: Any) -> str | None:
        """The endpoint ``mavlink.connection`` names (:meth:`MavlinkConfig.link_key`): robots on one share a process."""
        return cls.options(robot).link_key()

    @classmethod
    def check_mission(cls, robot: Any, sched: Any, hitl_on: bool) -> None:
        """``mavlink.use_autopilot_mission``: the navigation must be expressible as an uploaded mission."""
        from aerodaas.backends.mavlink.preflight import check_autopilot_mission

        check_autopilot_mission(robot, sched, hitl_on)

    @property
    def flies_uploaded_mission(self) -> bool:
        """``mavlink.use_autopilot_mission``: the pre-planned waypoints fly as an uploaded AUTO mission."""
        return bool(self.cfg.use_autopilot_mission)

    @property
    def failsafe_action(self) -> str:
        """``mavlink.on_failsafe``."""
        return self.cfg.on_failsafe

    @property
    def connects_first(self) -> bool:
        """A configured ``mavlink.target_system`` is claimed before ``"auto"`` robots pick the lowest id heard
        (:mod:`aerodaas.backends.mavlink.shared_link`)."""
        return isinstance(self.cfg.target_system, int)

    def __init__(self, cfg) -> None:  # cfg: aerodaas.config.RobotConfig
        super().__init__(cfg.id, cfg.home)
        self.cfg: MavlinkConfig = self.options(cfg)
        self.config_home: GeoPoint = cfg.home
        self._lock = threading.RLock()  # guards the state the I/O thread updates (every concern's)
        self._events: deque[dict[str, Any]] = deque(maxlen=2000)  # every concern's events (_event, drain_events)
        self._init_link()
        #: the robot's flight-envelope limits (aerodaas.config.Limits), also set on the vehicle (params.py)
        self.limits = cfg.limits
        #: the robot's safety rules: its geofence becomes the vehicle's own (fence.py, ``mavlink.fence``)
        self.safety = cfg.safety
        #: the parameter protocol (params.py), talking to the link through what it is given
        self.parameters = ParameterProtocol(self.robot_id, self.cfg, send=self.link.send,
                                            check_link=self.link.check_link, target=lambda: self.link.target,
                                            is_px4=lambda: self.autopilot == "px4")
        #: the command protocol (command.py): COMMAND_LONG/COMMAND_INT with their acknowledgements, mode changes
        self.commands = CommandProtocol(self.robot_id, self.cfg, send=self.link.send, check_link=self.link.check_link,
                                        target=lambda: self.link.target, heartbeat=self,
                                        boot_ms=lambda: self.clock.boot_ms, heartbeat_due=self.clock.heartbeat_due,
                                        status_text_since=self.status_texts.since, mode_params=self.link.mode_params,
                                        event=self._event)
        #: the state the autopilot streams: position, velocity, attitude, battery, GPS, home (telemetry.py)
        self.telemetry = VehicleTelemetry(self.robot_id, vehicle=self, on_boot_ms=self.clock.on_boot_ms,
                                          sample_time=self.clock.sample_time, t_connect=lambda: self.clock.t_connect,
                                          was_armed=lambda: self.link.was_armed, arming=lambda: self.actions.arming,
                                          on_position=lambda: self.mission.on_position(),
                                          on_gnss_speed=lambda *a: self.speed_limits.on_gnss_speed(*a),
                                          event=self._event, lock=self._lock)
        #: readiness, arming, disarming, take-off (action.py)
        self.actions = VehicleAction(self.robot_id, self.cfg, vehicle=self, commands=self.commands,
                                     check_link=self.link.check_link, event=self._event, lock=self._lock,
                                     readiness=self._readiness, home_for_flight=self.telemetry.home_for_flight,
                                     fix_altitude_reference=self.telemetry.fix_altitude_reference,
                                     stop_setpoints=self._stop_setpoints)
        #: guided/offboard targets, the autopilot's hold/land/return modes, the safe end (offboard.py)
        self.offboard = OffboardControl(self.robot_id, self.cfg, vehicle=self, commands=self.commands,
                                        actions=self.actions, send=self.link.send,
                                        target=lambda: self.link.target, boot_ms_out=self.clock.boot_ms_out,
                                        boot_ms=lambda: self.clock.boot_ms, live_since=lambda: self.clock.live_since,
                                        last_heartbeat=lambda: self.link.last_heartbeat,
                                        mode_changes=lambda: self.link.mode_changes,
                                        failsafe_undelivered=lambda: self.link.failsafe_undelivered,
                                        check_link=self.link.check_link, event=self._event, lock=self._lock)
        #: the mission protocol's transfers (transfer.py), talking to the link through what it is given
        self.transfers = MissionTransfer(self.robot_id, self.cfg, send=self.link.send,
                                         check_link=self.link.check_link, target=lambda: self.link.target,
                                         status_text_since=self.status_texts.since, event=self._event,
                                         wire_version=lambda: getattr(self.link.port.mav, "WIRE_PROTOCOL_VERSION",
                                                                      "2.0"))
        #: the vehicle's own mission (mission.py): upload, download, clear, start, progress
        self.mission = AutopilotMission(self.robot_id, vehicle=self, commands=self.commands, transfers=self.transfers,
                                        check_link=self.link.check_link, event=self._event, lock=self._lock,
                                        pin_altitude_reference=self.actions.pin_altitude_reference)
        #: the vehicle's own speed limits for ``limits``, over the parameter protocol (params.py)
        self.speed_limits = SpeedLimits(self.robot_id, self.limits, params=self.parameters, vehicle=self,
                                        event=self._event, lock=self._lock,
                                        speed_commanded=lambda: self.offboard.speed_commanded,
                                        change_speed_again=lambda: self.offboard.resend_speed())
        #: the vehicle's own geofence and rally points (fence.py), over the parameter protocol and the transfers
        self.fence = AutopilotFence(self.robot_id, self.cfg.fence, self.limits, self.safety, params=self.parameters,
                                    transfers=self.transfers, autopilot=lambda: self.autopilot,
                                    vehicle_time=lambda: self.t, check_link=self.link.check_link, event=self._event)
        self._cameras = CameraFinder(self.link)  # camera protocol v2 (camera.py), fed by link.py dispatch
        #: the gimbal concern (gimbal protocol v2): commands, GIMBAL_DEVICE_ATTITUDE_STATUS reports
        self.gimbal = GimbalConcern(self, cfg.gimbal)
        self.link.handlers = self._message_handlers()

    def _init_link(self) -> None:
        """The link's concerns: the status texts, the vehicle clock and the link itself (link.py). The link reaches
        the concerns made after it (commands, transfers, cameras, offboard, gimbal) through the callables given."""
        #: the autopilot's status texts (statustext.py): reassembled, quoted in refusals, reported
        self.status_texts = StatusTexts(self.robot_id, event=self._event)
        #: the vehicle clock from time_boot_ms (clock.py): the run's time t, its rate, missed heartbeats
        self.clock = VehicleClock(self.cfg, link_ok=lambda: self.link.link_ok,
                                  live_since=lambda now: self.link.live_since(now), event=self._event, lock=self._lock)
        #: MAVLink 2 signing with the vehicle's key (signing.py; NoSigning without ``mavlink.signing_key_file``)
        self.signing = make_signing(self.cfg.signing_key_file, self.robot_id, self._event)
        self.link = MavlinkLink(self.robot_id, self.cfg, clock=self.clock, texts=self.status_texts,  # link.py
                                signing=self.signing, event=self._event,
                                lock=self._lock, on_command_ack=lambda now, m: self.commands.on_command_ack(now, m),
                                on_mission_message=lambda m: self.transfers.offer(m),
                                on_component_message=lambda m: self._cameras.on_message(m),
                                command_long=self.command_long, mode_asked=lambda: self.commands.mode_asked,
                                setpoint=lambda: self.offboard.setpoint,
                                send_setpoint=lambda sp, now: self.offboard.send_due(sp, now),
                                stop_setpoints=lambda: self.offboard.stop_quiet(),
                                loss_timeout_s=lambda: self.offboard.loss_timeout_s,
                                extra_streams=lambda: self.gimbal.streams())

    def _message_handlers(self) -> dict[str, Handler]:
        """The handler of each message type the I/O thread hands on under ``_lock`` (link.py ``dispatch``; HEARTBEAT,
        STATUSTEXT, COMMAND_ACK and the mission protocol's messages are routed before this table)."""
        return {**self.telemetry.handlers(), "PARAM_VALUE": self.parameters.on_param_value,
                "MISSION_CURRENT": self.mission.on_mission_current,
                "MISSION_ITEM_REACHED": self.mission.on_mission_item_reached,
                "GIMBAL_DEVICE_ATTITUDE_STATUS": self.gimbal.on_message,
                "GIMBAL_MANAGER_INFORMATION": self.gimbal.on_message}

    # the link (aerodaas.backends.mavlink.link.MavlinkLink) and the vehicle clock (clock.VehicleClock)
    def connect(self, timeout_s: float | None = None) -> None:
        """Open the link (:meth:`MavlinkLink.open`: the autopilot's HEARTBEAT, its identity, the I/O thread, the
        telemetry streams and HOME_POSITION requested), wait for the first SYS_STATUS, then start the run's clock;
        on PX4 read COM_OF_LOSS_T, and make the vehicle's speed limits (``set_speed_limits``) and fence
        (``mavlink.fence.upload``) the robot's. Raises :class:`BackendError` after ``timeout_s`` (default
        ``connect_timeout_s``) seconds, naming the connection string; ValueError for a vehicle that is not a
        multirotor or an autopilot that cannot be identified; what applying the limits or the fence raises."""
        timeout = self.cfg.connect_timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        self.link.open(deadline, timeout)
        while True:
            with self._lock:
                ready = self.telemetry.sys_status_seen
            if ready:
                break
            if time.monotonic() > deadline:
                self.close()
                raise BackendError(f"robot {self.robot_id!r}: mavlink connection {self.cfg.connection!r}: the "
                                   f"autopilot sent HEARTBEAT but no SYS_STATUS within {timeout:g} s "
                                   "(telemetry streams not configured?)")
            time.sleep(0.01)
        with self._lock:
            self.clock.start()
            self.telemetry.clear_odometry()  # stamped on the clock before the connection's zero
        if self.autopilot == "px4":  # how long PX4 waits for our setpoints before its failsafe (offboard.py)
            got = self.read_parameters(["COM_OF_LOSS_T"]).get("COM_OF_LOSS_T")
            if got is not None and math.isfinite(got) and got > 0:
                self.offboard.loss_timeout_s = float(got)
            else:  # PX4's default 1 s, scaled as PX4 SITL's rcS scales it by its speed factor (never stricter)
                self.offboard.loss_timeout_s = max(1.0, self.clock.ratio)
            self._event("offboard_loss_timeout", seconds=self.offboard.loss_timeout_s, read=got is not None)
        if self.cfg.set_speed_limits:
            try:
                self.apply_speed_limits()
            except BaseException:
                self.close(safe_end=False)
                raise
        if self.cfg.fence.upload and not self.safety.geofence.is_empty:
            try:  # the autopilot's own fence, the second line behind our gate (fence.py)
                self.apply_fence()
            except BaseException:
                self.close(safe_end=False)
                raise

    def close(self, safe_end: bool = True) -> None:
        """Close the link (idempotent, never raises). With ``safe_end`` (default) a vehicle still armed is first
        brought down (:meth:`safe_end`), and parameters changed by :meth:`apply_speed_limits` are restored when
        ``restore_params`` says so and the vehicle is disarmed (never in flight: it would speed up). ``safe_end=False``
        hands the vehicle over as it is (``aerodaas mission upload --start``: the autopilot flies on)."""
        worker = self.speed_limits.worker  # a limit being lowered (params.py): finished before restoring parameters
        if worker is not None and worker is not threading.current_thread():
            worker.join(timeout=5.0)
        if self.link.running:
            if safe_end:
                try:
                    self.safe_end()
                except Exception as e:  # noqa: BLE001 - closing must go on
                    self._event("safe_end_failed", error=str(e))
                    log.warning("%s: safe end failed: %s", self.robot_id, e)
            if self.cfg.fence.restore_on_close and self.fence.has_saved:
                if self.link_ok and not self.armed:
                    self.restore_fence()
                else:
                    self._event("fence_not_restored", reason="link lost" if not self.link_ok else "still armed")
            if self.cfg.restore_params and self.parameters.changed:
                if worker is not None and worker.is_alive():  # its PARAM_SET echoes and ours would be mixed up
                    self._event("params_not_restored", reason="speed limit write in progress",
                                names=self.parameters.changed)
                elif self.link_ok and not self.armed:
                    self.restore_parameters()
                else:
                    self._event("params_not_restored", reason="link lost" if not self.link_ok else "still armed",
                                names=self.parameters.changed)
        self.link.close()

    def step(self, dt: float) -> None:
        """Telemetry arrives on the I/O thread; this reports that thread's failure (BackendError) and lowers the
        vehicle's speed limit when its estimator needs more margin (params.py :meth:`SpeedLimits.update`, then
        :meth:`SpeedLimits.resend_speed`)."""
        if self.link.io_error is not None:
            raise BackendError(f"robot {self.robot_id!r}: the MAVLink I/O thread failed: {self.link.io_error}")
        self.speed_limits.update()
        self.speed_limits.resend_speed()

    @property
    def t(self) -> float:
        """Vehicle seconds since :meth:`connect` (:attr:`VehicleClock.t`)."""
        return self.clock.t

    @property
    def clock_ratio(self) -> float:
        """Vehicle seconds per wall second (:attr:`VehicleClock.ratio`; 1 for a real vehicle)."""
        return self.clock.ratio

    @property
    def autopilot(self) -> Literal["ardupilot", "px4"] | None:
        """``"ardupilot"`` / ``"px4"`` once connected (:attr:`MavlinkLink.autopilot`)."""
        return self.link.autopilot

    @property
    def vehicle_type(self) -> str:
        """The HEARTBEAT's MAV_TYPE name (:attr:`MavlinkLink.vehicle_type`)."""
        return self.link.vehicle_type

    @property
    def messages_received(self) -> int:
        """Every message the receive path saw, unknown and malformed ones included."""
        return self.link.messages_received

    @property
    def failsafe(self) -> dict[str, Any] | None:
        """The autopilot's failsafe, when it entered one by itself (:attr:`MavlinkLink.failsafe`)."""
        return self.link.failsafe

    @property
    def armed(self) -> bool:
        """The armed flag of the autopilot's latest HEARTBEAT."""
        return self.link.armed

    @property
    def link_ok(self) -> bool:
        """HEARTBEATs keep coming (:attr:`MavlinkLink.link_ok`)."""
        return self.link.link_ok

    @property
    def mode(self) -> str:
        """The flight mode from the latest HEARTBEAT, in pymavlink's names (``GUIDED``, ``OFFBOARD``, ``LOITER``...)."""
        return self.link.mode

    # events of every concern, and the state the autopilot streams (aerodaas.backends.mavlink.telemetry)
    def _event(self, event: str, **fields: Any) -> None:
        self._events.append({"event": event, "t": round(self.t, 3), **fields})  # extrapolated while the link is down

    def drain_events(self) -> list[dict[str, Any]]:
        """See :meth:`~aerodaas.backends.base.VehicleBackend.drain_events`. Once an ``autopilot_failsafe`` event is
        handed out, targets may be sent again (the caller decides: ``mavlink.on_failsafe``; offboard.py)."""
        out = []
        while self._events:
            try:
                ev = self._events.popleft()
            except IndexError:
                break
            out.append(ev)
            if ev.get("event") == "autopilot_failsafe":
                with self._lock:
                    self.link.failsafe_delivered()
        return out

    def _readiness(self) -> Readiness:
        """The reports readiness is judged from (:meth:`VehicleTelemetry.readiness` with the link's). Caller holds
        ``_lock``."""
        return self.telemetry.readiness(self.link.system_status, self.status_texts.ekf_using_gps,
                                        self.link.ekf_report_unavailable)

    @property
    def position(self) -> np.ndarray:
        """:attr:`VehicleTelemetry.position`."""
        return self.telemetry.position

    @property
    def velocity(self) -> np.ndarray:
        """:attr:`VehicleTelemetry.velocity`."""
        return self.telemetry.velocity

    @property
    def yaw(self) -> float:
        """:attr:`VehicleTelemetry.yaw`."""
        return self.telemetry.yaw

    @property
    def in_air(self) -> bool:
        """:attr:`VehicleTelemetry.in_air`."""
        return self.telemetry.in_air

    @property
    def battery_pct(self) -> float:
        """:attr:`VehicleTelemetry.battery_pct`."""
        return self.telemetry.battery_pct

    @property
    def gps_fix_type(self) -> int:
        """:attr:`VehicleTelemetry.gps_fix_type`."""
        return self.telemetry.gps_fix_type

    @property
    def position_accuracy_m(self) -> float:
        """The GNSS receiver's horizontal accuracy (:attr:`VehicleTelemetry.gps_h_acc_m`, GPS_RAW_INT ``h_acc``);
        0 when the vehicle reports none."""
        return self.telemetry.gps_h_acc_m

    @property
    def home_received(self) -> bool:
        """:attr:`VehicleTelemetry.home_received`."""
        return self.telemetry.home_received

    @property
    def altitude_reference(self) -> float | None:
        """:attr:`VehicleTelemetry.altitude_reference`."""
        return self.telemetry.altitude_reference

    @property
    def sample_key(self) -> int:
        """:attr:`VehicleTelemetry.sample_key`."""
        return self.telemetry.sample_key

    def pose_sample(self) -> PoseSample:
        """:meth:`VehicleTelemetry.pose_sample`."""
        return self.telemetry.pose_sample()

    def odometry(self) -> Odometry:
        """:meth:`VehicleTelemetry.odometry`."""
        return self.telemetry.odometry()

    def drain_odometry(self, newest_only: bool = False) -> list[Odometry]:
        """:meth:`VehicleTelemetry.drain_odometry`."""
        return self.telemetry.drain_odometry(newest_only)

    # the command protocol (aerodaas.backends.mavlink.command.CommandProtocol)
    def command_long(self, name: str, command: int, *params: float, retries: int | None = None,
                     timeout_s: float | None = None) -> None:
        """COMMAND_LONG ``command`` with its COMMAND_ACK awaited (:meth:`CommandProtocol.command_long`)."""
        self.commands.command_long(name, command, *params, retries=retries, timeout_s=timeout_s)

    def command_int(self, name: str, command: int, frame: int, params: tuple[float, float, float, float], x: int,
                    y: int, z: float, retries: int | None = None, timeout_s: float | None = None) -> None:
        """COMMAND_INT ``command`` with its COMMAND_ACK awaited (:meth:`CommandProtocol.command_int`)."""
        self.commands.command_int(name, command, frame, params, x, y, z, retries=retries, timeout_s=timeout_s)

    def set_mode(self, name: str, confirm_s: float | None = None) -> None:
        """Switch to flight mode ``name``, confirmed by the HEARTBEAT (:meth:`CommandProtocol.set_mode`)."""
        self.commands.set_mode(name, confirm_s)

    @property
    def command_rtt_ms(self) -> list[float]:
        """Acknowledged command round trips, wall milliseconds (:attr:`CommandProtocol.rtt_ms`)."""
        return self.commands.rtt_ms

    # parameters (aerodaas.backends.mavlink.params: ParameterProtocol, SpeedLimits)
    def read_parameters(self, names: list[str], wait_s: float | None = None) -> dict[str, float]:
        """:meth:`ParameterProtocol.read`."""
        return self.parameters.read(names, wait_s)

    def set_parameter(self, name: str, value: float, wait_s: float | None = None, integer: bool = False) -> float:
        """:meth:`ParameterProtocol.set`."""
        return self.parameters.set(name, value, wait_s, integer)

    def restore_parameters(self) -> dict[str, float]:
        """Put back the values the vehicle had before :meth:`apply_speed_limits` changed them
        (:meth:`ParameterProtocol.restore`, reported as events). Returns what was restored. Never raises."""
        return self.parameters.restore(self._event)

    def xy_speed_cap(self) -> float:
        """The horizontal speed (m/s) the vehicle is limited to for the robot's ``limits.max_speed``
        (:meth:`SpeedLimits.xy_speed_cap`)."""
        return self.speed_limits.xy_speed_cap()

    def apply_speed_limits(self) -> dict[str, float]:
        """Make the vehicle's own speed limits the robot's ``limits`` (:meth:`SpeedLimits.apply`); returns the
        verified values (firmware units)."""
        return self.speed_limits.apply()

    # readiness, arming, take-off (aerodaas.backends.mavlink.action.VehicleAction)
    def not_ready_reasons(self) -> list[str]:
        """What the autopilot's own reports say is still missing before it can arm in a guided mode
        (:meth:`VehicleAction.not_ready_reasons`); empty when ready. Never blocks."""
        return self.actions.not_ready_reasons()

    def arm(self) -> None:
        """Arm for a guided flight, bounded by ``arm_timeout_s`` (:meth:`VehicleAction.arm`)."""
        self.actions.arm()

    def disarm(self) -> None:
        """MAV_CMD_COMPONENT_ARM_DISARM(0); autopilots refuse it in flight (:meth:`VehicleAction.disarm`)."""
        self.actions.disarm()

    def takeoff(self, altitude_m: float) -> None:
        """MAV_CMD_NAV_TAKEOFF to ``altitude_m`` metres above the take-off point (:meth:`VehicleAction.takeoff`)."""
        self._require_navigable("takeoff")
        self.actions.takeoff(altitude_m)

    # guided control (aerodaas.backends.mavlink.offboard.OffboardControl)
    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        """Fly to ``target_enu`` (ENU metres from home) at most at ``speed`` m/s (:meth:`OffboardControl.goto`)."""
        self._require_navigable("goto")
        self.offboard.goto(target_enu, speed)

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        """Hold ENU velocity ``v_enu`` (m/s) and yaw rate (deg/s) (:meth:`OffboardControl.set_velocity`)."""
        self._require_navigable("set_velocity")
        self.offboard.set_velocity(v_enu, yaw_rate_dps)

    def hold(self) -> None:
        """Hover here (:meth:`OffboardControl.hold`)."""
        self._require_navigable("hold")
        self.offboard.hold()

    def land(self) -> None:
        """LAND mode: descend and land here (:meth:`OffboardControl.land`)."""
        self._require_navigable("land")
        self.offboard.land()

    def return_to_launch(self) -> bool:
        """RTL mode (:meth:`OffboardControl.return_to_launch`). Returns True."""
        self._require_navigable("return_to_launch")
        return self.offboard.return_to_launch()

    def release(self) -> None:
        """Stop streaming targets and leave the vehicle to the mode it is in (:meth:`OffboardControl.release`)."""
        self.offboard.release()

    def safe_end(self) -> str:
        """Leave the vehicle safe before the link closes (:meth:`OffboardControl.safe_end`); returns what was done."""
        return self.offboard.safe_end()

    def _stop_setpoints(self) -> None:
        self.offboard.stop()

    # the mission (aerodaas.backends.mavlink.mission.AutopilotMission)
    def upload_mission(self, mission: Any, *, takeoff_altitude: float | None = None,
                       final_action: Literal["land", "rtl", "hover"] = "hover") -> list[MissionItem]:
        """Upload a mission with the MISSION_ITEM_INT protocol (:meth:`AutopilotMission.upload`); returns the items
        as sent."""
        return self.mission.upload(mission, takeoff_altitude=takeoff_altitude, final_action=final_action)

    def download_mission(self) -> MissionPlan:
        """Download the autopilot's mission (:meth:`AutopilotMission.download`)."""
        return self.mission.download()

    def clear_mission(self) -> None:
        """MISSION_CLEAR_ALL; waits for MISSION_ACK (:meth:`AutopilotMission.clear`)."""
        self.mission.clear()

    def start_mission(self) -> None:
        """Fly the uploaded mission (:meth:`AutopilotMission.start`): our target stream stops first, and the vehicle
        is ours to bring down (:meth:`safe_end`)."""
        self._require_navigable("start_mission")
        self._stop_setpoints()
        self.actions.take_control()
        self.mission.start()

    # the mission protocol's typed transfers (aerodaas.backends.mavlink.transfer.MissionTransfer)
    def upload_items(self, mission_type: int, wire: list[Wire]) -> None:
        """:meth:`~aerodaas.backends.mavlink.transfer.MissionTransfer.upload_items`."""
        self.transfers.upload_items(mission_type, wire)

    def download_items(self, mission_type: int) -> list[Wire]:
        """:meth:`~aerodaas.backends.mavlink.transfer.MissionTransfer.download_items`."""
        return self.transfers.download_items(mission_type)

    # the vehicle's fence (aerodaas.backends.mavlink.fence.AutopilotFence)
    def fence_parameters(self, fence: GeofenceConfig, have: dict[str, float] | None = None) \
            -> dict[str, tuple[float, bool]]:
        """The fence parameters for ``fence`` on this autopilot (:meth:`AutopilotFence.fence_parameters`)."""
        return self.fence.fence_parameters(fence, have)

    def apply_fence(self, fence: GeofenceConfig | None = None) -> dict[str, Any]:
        """Make ``fence`` (default ``safety.geofence``) the vehicle's own, verified (:meth:`AutopilotFence.apply`)."""
        return self.fence.apply(fence)

    def upload_rally(self, points: list[tuple[float, float, float]]) -> int:
        """Upload rally points and read them back (:meth:`AutopilotFence.upload_rally`); returns how many."""
        return self.fence.upload_rally(points)

    def restore_fence(self) -> bool:
        """Put back the vehicle's fence from before :meth:`apply_fence` (:meth:`AutopilotFence.restore`)."""
        return self.fence.restore()

    @property
    def fence_applied(self) -> dict[str, Any] | None:
        """What :meth:`apply_fence` verified, or None (:attr:`AutopilotFence.applied`)."""
        return self.fence.applied

    def discover_video_stream(self, request: Any) -> Any:
        """The video stream a camera of the connected vehicle announces (camera protocol v2), for a camera with
        ``source: "mavlink"``: ``request`` an :class:`aerodaas.video.discovery.StreamRequest`, returns its
        :class:`~aerodaas.video.discovery.DiscoveredStream`. Raises
        :class:`~aerodaas.video.discovery.StreamDiscoveryError` after ``request.timeout_s`` without one, LinkLost
        when the link is down."""
        self.link.check_link("camera discovery")
        return self._cameras.discover(request, self.link.target[1])

    # the gimbal (aerodaas.backends.mavlink.gimbal.GimbalConcern)
    def point_gimbal(self, cmd: Any) -> None:
        """Point the vehicle's gimbal (:meth:`GimbalConcern.point`)."""
        self.gimbal.point(cmd)

    def gimbal_attitude(self) -> Any:
        """The latest GIMBAL_DEVICE_ATTITUDE_STATUS as a GimbalAttitude (None before the first)."""
        return self.gimbal.latest()

    def drain_gimbal(self) -> list:
        """Every GIMBAL_DEVICE_ATTITUDE_STATUS not handed out yet, oldest first."""
        return self.gimbal.drain()
