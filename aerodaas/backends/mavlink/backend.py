"""The MAVLink vehicle backend: one class holding the concern objects (commands, parameters, mission transfers, mission,
actions, guidance, speed limits, telemetry, fence, gimbal, link, clock, signing, status texts; see the package
docstring)."""
from __future__ import annotations

import math
import threading
import time
from typing import Any

from aerodaas.config import MavlinkConfig
from aerodaas.model.types import GeoPoint
from aerodaas.backends.base import BackendError, VehicleBackend, VehicleState
from aerodaas.backends.mavlink.action import VehicleAction
from aerodaas.backends.mavlink.camera import CameraFinder
from aerodaas.backends.mavlink.clock import VehicleClock
from aerodaas.backends.mavlink.command import CommandProtocol
from aerodaas.backends.mavlink.events import EventLog
from aerodaas.backends.mavlink.fence import AutopilotFence
from aerodaas.backends.mavlink.gimbal import GimbalConcern
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink.mission import AutopilotMission
from aerodaas.backends.mavlink.offboard import OffboardControl
from aerodaas.backends.mavlink.params import ParameterProtocol, SpeedLimits
from aerodaas.backends.mavlink.preflight import (check_autopilot_fence, check_autopilot_mission, check_shared_links,
                                                 resolve_signing_key)
from aerodaas.backends.mavlink.signing import SignedOnly, make_signing
from aerodaas.backends.mavlink.statustext import StatusTexts
from aerodaas.backends.mavlink.telemetry import VehicleTelemetry
from aerodaas.backends.mavlink.transfer import MissionTransfer
from aerodaas.backends.mavlink._common import log


class MavlinkBackend(VehicleBackend):
    """An ArduPilot Copter or PX4 multicopter reached over MAVLink (settings: :class:`~aerodaas.config.MavlinkConfig`).

    ``clock == "vehicle"``: :attr:`t` is the autopilot's ``time_boot_ms`` (seconds since :meth:`connect`), wall time
    until a timestamped message arrives; while the link is lost it runs on from the last sample at the measured
    vehicle/wall rate (so the runtime's control ticks, and its LINK_LOST state, go on). Positions are ENU metres
    from the vehicle's HOME_POSITION (the configured home until the vehicle reports one; ``state().home``).
    Besides the :class:`VehicleBackend` contract (:meth:`state`, and :meth:`discover_video_stream` for a camera with
    ``source: "mavlink"``), the MAVLink concerns are its public members, used directly, as the contract's groups
    are: ``actions`` (the command group: ``arm``/``disarm``/``takeoff``, ``not_ready_reasons``), ``guidance``
    (the command group: ``goto``/``set_velocity``/``hold``/``land``/``return_to_launch``, and ``release``,
    ``safe_end``), ``telemetry`` (the position samples: ``odometry``/``drain_odometry``/``pose_sample``/
    ``sample_key``; ``home``, ``home_received``, ``gps_fix_type``, ``altitude_reference``), ``mission``
    (``upload``/``download``/``clear``/``start``, for ``flies_uploaded_mission``), ``gimbal`` (``point``/
    ``latest``/``drain``), ``commands`` (COMMAND_LONG/INT, ``set_mode``, ``rtt_ms``), ``parameters``
    (``read``/``set``/``restore``), ``speed_limits``, ``transfers`` (typed mission, fence and rally items),
    ``fence`` (``apply``/``upload_rally``/``restore``: the vehicle's own geofence, made the robot's
    ``safety.geofence`` on connect when ``mavlink.fence.upload``), ``link`` (``autopilot``: ``"ardupilot"``/
    ``"px4"``, ``mode``, ``vehicle_type``, ``failsafe``, ``messages_received``), ``clock`` (``t``, ``ratio``),
    ``signed_only`` (``mavlink.require_signing``), ``events``, ``status_texts``, ``cameras`` (package docstring).
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
        check_autopilot_fence(robot, where)

    #: ``mavlink.signing_key_file`` resolved and checked before Ray starts (preflight.py)
    resolve_files = classmethod(resolve_signing_key)

    @classmethod
    def check_fleet(cls, robots: list[tuple[int, Any]]) -> None:
        """Robots on one link (``mavlink.connection``) speak as one ground station to distinct system ids."""
        check_shared_links(robots)

    @classmethod
    def link_key(cls, robot: Any) -> str | None:
        """The endpoint ``mavlink.connection`` names (:meth:`MavlinkConfig.link_key`): robots on one share a process."""
        return cls.options(robot).link_key()

    @classmethod
    def check_mission(cls, robot: Any, sched: Any, hitl_on: bool) -> None:
        """``mavlink.use_autopilot_mission``: the navigation must be expressible as an uploaded mission."""
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
        """The concern objects, each given its collaborators (as MAVSDK composes a ``System`` of plugins: each is
        made on the link and registers what it receives). Raises what :func:`make_signing` raises (key file)."""
        super().__init__(cfg.id, None)  # the home is the telemetry's: the vehicle's HOME_POSITION once it reports one
        self.cfg: MavlinkConfig = self.options(cfg)
        self._lock = threading.RLock()  # guards the state the I/O thread updates (every concern's)
        #: the vehicle clock from time_boot_ms (clock.py): the run's time t, its rate, missed heartbeats
        self.clock = VehicleClock(self.cfg, lock=self._lock)
        #: every concern's events, stamped with the vehicle clock (events.py; drain_events)
        self.events = EventLog(self.clock)
        self._compose(cfg)
        self.config_home: GeoPoint = cfg.home

    def _compose(self, cfg) -> None:
        """Make the concerns in the order of what each needs. ``cfg``: the robot's configuration."""
        rid, ev, lock = cfg.id, self.events, self._lock
        #: the robot's flight-envelope limits (aerodaas.config.Limits), also set on the vehicle (params.py)
        self.limits = cfg.limits
        #: the robot's safety rules: its geofence becomes the vehicle's own (fence.py, ``mavlink.fence``)
        self.safety = cfg.safety
        #: the autopilot's status texts (statustext.py): reassembled, quoted in refusals, reported
        self.status_texts = StatusTexts(rid, event=ev)
        #: MAVLink 2 signing with the vehicle's key (signing.py; NoSigning without ``mavlink.signing_key_file``)
        self.signing = make_signing(self.cfg.signing_key_file, rid, ev)
        #: the link (link.py): connection, HEARTBEAT, the I/O thread that hands each message to its concern
        self.link = MavlinkLink(rid, self.cfg, clock=self.clock, texts=self.status_texts, signing=self.signing,
                                event=ev, lock=lock)
        #: ``mavlink.require_signing`` for what moves the vehicle (signing.py), asked by actions, guidance, mission
        self.signed_only = SignedOnly(rid, self.cfg, signing=self.signing, link=self.link)
        #: the command protocol (command.py): COMMAND_LONG/COMMAND_INT with their acknowledgements, mode changes
        self.commands = CommandProtocol(rid, self.cfg, link=self.link, clock=self.clock, texts=self.status_texts,
                                        event=ev)
        #: the parameter protocol (params.py)
        self.parameters = ParameterProtocol(rid, self.cfg, link=self.link)
        #: the state the autopilot streams: position, velocity, attitude, battery, GPS, home (telemetry.py); the
        #: position samples the runtime records (the contract's ``telemetry``)
        self.telemetry = VehicleTelemetry(rid, cfg.home, link=self.link, clock=self.clock, event=ev,
                                          lock=lock)
        #: the vehicle's own speed limits for ``limits``, over the parameter protocol (params.py)
        self.speed_limits = SpeedLimits(rid, self.limits, params=self.parameters, link=self.link, clock=self.clock,
                                        telemetry=self.telemetry, event=ev, lock=lock)
        #: the command group ``guidance``: guided/offboard targets, the autopilot's hold/land/return modes, the
        #: release and the safe end (offboard.py)
        self.guidance = OffboardControl(rid, self.cfg, link=self.link, clock=self.clock, telemetry=self.telemetry,
                                        speed_limits=self.speed_limits, commands=self.commands,
                                        signed=self.signed_only, event=ev, lock=lock)
        #: the command group ``actions``: readiness, arming, disarming, take-off (action.py)
        self.actions = VehicleAction(rid, self.cfg, link=self.link, clock=self.clock, texts=self.status_texts,
                                     commands=self.commands, telemetry=self.telemetry, offboard=self.guidance,
                                     signed=self.signed_only, event=ev, lock=lock)
        #: the mission protocol's transfers (transfer.py)
        self.transfers = MissionTransfer(rid, self.cfg, link=self.link, texts=self.status_texts, event=ev)
        #: the vehicle's own mission (mission.py): upload, download, clear, start, progress
        self.mission = AutopilotMission(rid, link=self.link, telemetry=self.telemetry, speed_limits=self.speed_limits,
                                        commands=self.commands, transfers=self.transfers, actions=self.actions,
                                        offboard=self.guidance, signed=self.signed_only, event=ev, lock=lock)
        #: the vehicle's own geofence and rally points (fence.py), over the parameter protocol and the transfers
        self.fence = AutopilotFence(rid, self.cfg.fence, self.limits, self.safety, params=self.parameters,
                                    transfers=self.transfers, link=self.link, clock=self.clock, event=ev)
        #: the cameras of the vehicle's system and their video streams (camera.py, camera protocol v2)
        self.cameras = CameraFinder(self.link)
        #: the gimbal concern (gimbal protocol v2): commands, GIMBAL_DEVICE_ATTITUDE_STATUS reports
        self.gimbal = GimbalConcern(cfg.gimbal, commands=self.commands, telemetry=self.telemetry, clock=self.clock,
                                    link=self.link)

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
        if self.link.autopilot == "px4":  # how long PX4 waits for our setpoints before its failsafe (offboard.py)
            got = self.parameters.read(["COM_OF_LOSS_T"]).get("COM_OF_LOSS_T")
            if got is not None and math.isfinite(got) and got > 0:
                self.guidance.loss_timeout_s = float(got)
            else:  # PX4's default 1 s, scaled as PX4 SITL's rcS scales it by its speed factor (never stricter)
                self.guidance.loss_timeout_s = max(1.0, self.clock.ratio)
            self.events("offboard_loss_timeout", seconds=self.guidance.loss_timeout_s, read=got is not None)
        if self.cfg.set_speed_limits:
            try:
                self.speed_limits.apply()
            except BaseException:
                self.close(safe_end=False)
                raise
        if self.cfg.fence.upload and not self.safety.geofence.is_empty:
            try:  # the autopilot's own fence, the second line behind our gate (fence.py)
                self.fence.apply()
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
                    self.guidance.safe_end()
                except Exception as e:  # noqa: BLE001 - closing must go on
                    self.events("safe_end_failed", error=str(e))
                    log.warning("%s: safe end failed: %s", self.robot_id, e)
            link_ok, armed = self.link.link_ok, self.link.armed
            if self.cfg.fence.restore_on_close and self.fence.has_saved:
                if link_ok and not armed:
                    self.fence.restore()
                else:
                    self.events("fence_not_restored", reason="link lost" if not link_ok else "still armed")
            link_ok, armed = self.link.link_ok, self.link.armed  # again: restoring the fence took time
            if self.cfg.restore_params and self.parameters.changed:
                if worker is not None and worker.is_alive():  # its PARAM_SET echoes and ours would be mixed up
                    self.events("params_not_restored", reason="speed limit write in progress",
                                names=self.parameters.changed)
                elif link_ok and not armed:
                    self.parameters.restore(self.events)
                else:
                    self.events("params_not_restored", reason="link lost" if not link_ok else "still armed",
                                names=self.parameters.changed)
        self.link.close()

    def step(self, dt: float) -> None:
        """Telemetry arrives on the I/O thread; this reports that thread's failure (BackendError) and lowers the
        vehicle's speed limit when its estimator needs more margin (params.py :meth:`SpeedLimits.update`, then
        :meth:`SpeedLimits.resend_speed`)."""
        if self.link.io_error is not None:
            raise BackendError(f"robot {self.robot_id!r}: the MAVLink I/O thread failed: {self.link.io_error}")
        self.speed_limits.update()
        self.speed_limits.resend_speed(self.guidance)

    def state(self) -> VehicleState:
        """The vehicle now, read under the I/O thread's lock: position, velocity, attitude and battery as the autopilot
        streams them (:class:`VehicleTelemetry`: ENU metres from its home, the configured one until the autopilot
        reports its HOME_POSITION, ENU m/s, degrees, percent; in-air
        from EXTENDED_SYS_STATE's landed state, else armed and above 0.3 m; the GNSS receiver's horizontal accuracy
        from GPS_RAW_INT ``h_acc``, 0 when it reports none), armed and flight mode (pymavlink's names: ``GUIDED``,
        ``OFFBOARD``, ``LOITER``...) from the latest HEARTBEAT, link health (HEARTBEATs keep coming,
        :attr:`MavlinkLink.link_ok`), at :attr:`VehicleClock.t`."""
        tel, link = self.telemetry, self.link
        with self._lock:
            roll, pitch, yaw = tel.attitude
            return VehicleState(t=self.clock.t, position=tel.position, velocity=tel.velocity, roll=roll, pitch=pitch,
                                yaw=yaw, battery_pct=tel.battery_pct, armed=link.armed, in_air=tel.in_air,
                                link_ok=link.link_ok, mode=link.mode, position_accuracy_m=tel.gps_h_acc_m,
                                home=tel.home)

    # events of every concern (events.py EventLog), and the state the autopilot streams (telemetry.py)
    def drain_events(self) -> list[dict[str, Any]]:
        """See :meth:`~aerodaas.backends.base.VehicleBackend.drain_events`. Once an ``autopilot_failsafe`` event is
        handed out, targets may be sent again (the caller decides: ``mavlink.on_failsafe``; offboard.py)."""
        out = self.events.drain()
        for ev in out:
            if ev.get("event") == "autopilot_failsafe":
                with self._lock:
                    self.link.failsafe_delivered()
        return out

    def discover_video_stream(self, request: Any) -> Any:
        """The video stream a camera of the connected vehicle announces (camera protocol v2), for a camera with
        ``source: "mavlink"``: ``request`` an :class:`aerodaas.video.discovery.StreamRequest`, returns its
        :class:`~aerodaas.video.discovery.DiscoveredStream`. Raises
        :class:`~aerodaas.video.discovery.StreamDiscoveryError` after ``request.timeout_s`` without one, LinkLost
        when the link is down."""
        self.link.check_link("camera discovery")
        return self.cameras.discover(request, self.link.target[1])
