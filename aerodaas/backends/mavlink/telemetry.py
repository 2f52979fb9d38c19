"""Telemetry: the state the autopilot streams (position, velocity, attitude, battery, GPS, landed state, home;
mission progress is the mission's, :mod:`.mission`) and the :class:`~aerodaas.backends.base.VehicleBackend` state
built from it. A concern object of :class:`~aerodaas.backends.mavlink.MavlinkBackend` (:class:`VehicleTelemetry`)."""
from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np

from aerodaas.backends.base import PoseSample, VehicleBackend
from aerodaas.model.geo import enu_to_geodetic, geodetic_to_enu
from aerodaas.model.types import Attitude, GeoPoint, Odometry
from aerodaas.backends.mavlink.clock import VehicleClock
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink._common import M


#: position samples kept for :meth:`VehicleTelemetry.drain_odometry` (60 vehicle seconds at the default 10 Hz
#: stream; the drone's clock thread drains them every step, so only a thread held up for that long loses any)
ODOMETRY_QUEUE = 600

#: a message handler of the I/O thread (link.py ``MavlinkLink.dispatch``), called under the backend's lock
Handler = Callable[[Any], None]


@dataclass(frozen=True)
class Readiness:
    """What the autopilot has reported about its readiness to arm (telemetry and HEARTBEAT, read together under the
    backend's lock): GPS_RAW_INT ``fix_type`` (-1 before any report), whether HOME_POSITION came, SYS_STATUS
    ``onboard_control_sensors_present`` / ``_health`` (0 before any) and every health bit ever reported, the
    EKF_STATUS_REPORT / ESTIMATOR_STATUS flags (None before any), HEARTBEAT ``system_status`` and armed flag,
    whether ArduPilot's "EKFn IMUm is using GPS" was seen, and whether EKF_STATUS_REPORT will never come (its
    stream refused, or the legacy REQUEST_DATA_STREAM in use)."""

    gps_fix: int
    home_received: bool
    sensors_present: int
    sensors_health: int
    health_seen: int
    ekf_flags: int | None
    system_status: int
    armed: bool
    ekf_using_gps: bool
    ekf_report_unavailable: bool


class PositionListener(Protocol):
    """Told of each new position sample (mission.py :class:`~aerodaas.backends.mavlink.mission.AutopilotMission`:
    its arrival check), on the I/O thread under the backend's lock."""

    def on_position(self) -> None: ...


class GnssSpeedListener(Protocol):
    """Told of each GPS_RAW_INT ground speed (params.py :class:`~aerodaas.backends.mavlink.params.SpeedLimits`: the
    estimator's margin): GNSS speed m/s, the estimate's horizontal speed m/s, whether that estimate is steady."""

    def on_gnss_speed(self, gnss_speed_mps: float, est_hspeed: float, est_steady: bool) -> None: ...


class VehicleTelemetry:
    """The vehicle's state as its streams report it (see the module docstring), fed by the I/O thread through the
    handlers of :meth:`handlers` under the backend's lock.

    It owns the ENU origin :attr:`home` (the configured ``home``, moved to the autopilot's HOME_POSITION) and is
    given its collaborators: ``link`` (the HEARTBEAT's armed flag, armed at least once since connect; the
    telemetry registers its message handlers with it), ``clock`` (the vehicle clock its ``time_boot_ms`` feed),
    ``event`` (records a backend event) and ``lock`` (the backend's lock). :attr:`arming` is set while
    :meth:`~aerodaas.backends.mavlink.action.VehicleAction.arm` runs. Listeners: :meth:`notify_positions`,
    :meth:`notify_gnss_speed`."""

    def __init__(self, robot_id: str, home: GeoPoint, *, link: MavlinkLink, clock: VehicleClock,
                 event: Callable[..., None], lock: threading.RLock) -> None:
        self.robot_id, self._link, self._clock, self._lock, self._event = robot_id, link, clock, lock, event
        #: the ENU origin (WGS-84 degrees, metres AMSL): the configured home until the autopilot reports its own
        self.home = home
        #: an :meth:`~aerodaas.backends.mavlink.action.VehicleAction.arm` is under way (set by the actions)
        self.arming = False
        self._position_listeners: list[PositionListener] = []
        self._gnss_listeners: list[GnssSpeedListener] = []
        for message_type, handler in self.handlers().items():
            link.handle(message_type, handler)
        self._pos = np.zeros(3)
        self._pos_t = 0.0  # vehicle time (raw clock, s) of the position sample in _pos
        self._pos_seq = 0  # position samples received
        #: the odometry of each position sample not yet drained (drain_odometry), oldest first
        self._odom_q: deque[Odometry] = deque(maxlen=ODOMETRY_QUEUE)
        self._odom_q_dropped = 0  # samples pushed out of the full queue since it was last drained
        self._odom_q_drained = False  # drained once: the run takes samples now, an overflow is a loss
        self._vel = np.zeros(3)
        self._est_hspeed = 0.0  # its horizontal speed, m/s (_set_velocity) ...
        self._est_steady = False  # ... changed at most at 1 m/s^2 since the sample before ...
        self._est_ms: int | None = None  # ... at this time_boot_ms
        self._att = (0.0, 0.0, 90.0)  # roll, pitch deg; yaw ENU deg
        self._geo: GeoPoint | None = None
        self._rel_alt = 0.0
        self._has_global = False
        self._local_ned: tuple[float, ...] | None = None
        self._local_wall = 0.0
        self._landed_state = 0
        self._landed_wall = 0.0
        self._battery: float | None = None
        self._battery_v = 0.0
        self._battery_from = ""
        self._gps_fix = -1
        self._gps_h_acc = 0.0  # m, GPS_RAW_INT h_acc; 0: not reported
        self._sensors: tuple[int, int, int] | None = None
        self._home_received = False
        self._home_after: GeoPoint | None = None  # the autopilot's home after a flight, when it moved (reported)
        self._att_wall = 0.0
        self._ekf_flags: int | None = None  # EKF_STATUS_REPORT (ArduPilot) / ESTIMATOR_STATUS (PX4) flags
        self._health_seen = 0  # every SYS_STATUS health bit ever reported
        self._alt_ref: float | None = None  # AMSL metres of the take-off point (fixed at arming)
        self._home_moved_alt = 0.0

    def notify_positions(self, listener: PositionListener) -> None:
        """Tell ``listener`` of each new position sample from now on."""
        self._position_listeners.append(listener)

    def notify_gnss_speed(self, listener: GnssSpeedListener) -> None:
        """Tell ``listener`` of each GNSS ground speed from now on."""
        self._gnss_listeners.append(listener)

    def handlers(self) -> dict[str, Handler]:
        """The handler of each telemetry message type (MAVLink message name), for the I/O thread's dispatch."""
        return {"GLOBAL_POSITION_INT": self.on_global_position_int, "LOCAL_POSITION_NED": self.on_local_position_ned,
                "ATTITUDE": self.on_attitude, "SYSTEM_TIME": self.on_system_time, "SYS_STATUS": self.on_sys_status,
                "BATTERY_STATUS": self.on_battery_status, "GPS_RAW_INT": self.on_gps_raw_int,
                "EXTENDED_SYS_STATE": self.on_extended_sys_state, "HOME_POSITION": self.on_home_position,
                "EKF_STATUS_REPORT": self.on_ekf_status_report, "ESTIMATOR_STATUS": self.on_estimator_status}

    def on_global_position_int(self, msg: Any) -> None:
        """GLOBAL_POSITION_INT: the position (ENU from home, height above the altitude reference), its velocity
        and heading when nothing fresher came. Caller holds ``_lock``."""
        self._boot_ms(msg.time_boot_ms)
        if msg.lat == 0 and msg.lon == 0:
            return  # ArduPilot sends zeros before its position estimate exists
        lat, lon = msg.lat / 1e7, msg.lon / 1e7
        self._geo = GeoPoint(lat=lat, lon=lon, alt=msg.alt / 1000.0)
        self._rel_alt = msg.relative_alt / 1000.0
        e, n, _ = geodetic_to_enu(lat, lon, self.home.alt, self.home)
        self._pos = np.array([e, n, self._height()])
        self._new_sample(msg.time_boot_ms)
        self._has_global = True
        for listener in self._position_listeners:
            listener.on_position()
        if time.monotonic() - self._local_wall > 1.0:  # no fresher LOCAL_POSITION_NED velocity
            v_ned = (msg.vx / 100.0, msg.vy / 100.0, msg.vz / 100.0)
            self._set_velocity(VehicleBackend.ned_to_enu(v_ned), msg.time_boot_ms)
        if msg.hdg != 65535 and time.monotonic() - self._att_wall > 1.0:  # no ATTITUDE lately
            self._att = (self._att[0], self._att[1], VehicleBackend.enu_yaw_from_heading(msg.hdg / 100.0))
        self._queue_odometry()

    def _height(self) -> float:
        """Metres above the altitude reference (the take-off point's AMSL altitude, fixed at arming: a frame that
        does not move), else above home (``relative_alt``) before the first arming. Caller holds ``_lock``."""
        if self._alt_ref is not None and self._geo is not None:
            return self._geo.alt - self._alt_ref
        return self._rel_alt

    def fix_altitude_reference(self) -> None:
        """Fix the altitude reference (AMSL metres) for this flight: the vehicle's own AMSL altitude
        (GLOBAL_POSITION_INT ``alt``) where it stands, or, if already in the air, its home altitude (``alt -
        relative_alt``); the configured/received home altitude without a global position. Every height read and
        commanded is against it, not against a HOME_POSITION that PX4 keeps re-estimating after take-off
        (``COM_HOME_EN``, commander ``HomePosition::update``)."""
        with self._lock:
            if self._geo is None:
                ref = self.home.alt
            elif self.in_air:
                ref = self._geo.alt - self._rel_alt
            else:
                ref = self._geo.alt
            self._alt_ref = ref
            if self._geo is not None:
                self._pos = np.array([self._pos[0], self._pos[1], self._height()])
        self._event("altitude_reference", amsl_m=round(ref, 3), home_amsl_m=round(self.home.alt, 3))

    @property
    def altitude_reference(self) -> float | None:
        """The AMSL altitude (metres) heights are measured from since arming, None before the first arming."""
        return self._alt_ref

    def on_ekf_status_report(self, msg: Any) -> None:
        """ArduPilot EKF_STATUS_REPORT: ``flags`` (EKF_STATUS_FLAGS) for readiness."""
        self._ekf_flags = int(msg.flags)

    def on_estimator_status(self, msg: Any) -> None:
        """PX4 ESTIMATOR_STATUS: ``flags`` (ESTIMATOR_STATUS_FLAGS) for readiness."""
        self._ekf_flags = int(msg.flags)

    def on_local_position_ned(self, msg: Any) -> None:
        """LOCAL_POSITION_NED: the velocity, and the position (ENU from the EKF origin) without a global one.
        Caller holds ``_lock``."""
        self._boot_ms(msg.time_boot_ms)
        self._local_ned = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)
        self._local_wall = time.monotonic()
        self._set_velocity(VehicleBackend.ned_to_enu((msg.vx, msg.vy, msg.vz)), msg.time_boot_ms)
        if not self._has_global:  # no global position (indoors): ENU from the EKF origin
            self._pos = VehicleBackend.ned_to_enu((msg.x, msg.y, msg.z))
            self._new_sample(msg.time_boot_ms)
            self._queue_odometry()

    def _set_velocity(self, v_enu: np.ndarray, ms: int) -> None:
        """The estimate's velocity (ENU m/s) at ``time_boot_ms`` ``ms``. Its horizontal speed is what a GNSS
        speed is compared with (params.py ``SpeedLimits.on_gnss_speed``) while it is steady (changed at most at 1 m/s^2 since
        the sample before): the two streams are not sampled together, and in an acceleration the difference of a
        period is no overshoot (3 m/s^2 over a 0.2 s period is 0.6 m/s)."""
        h = math.hypot(float(v_enu[0]), float(v_enu[1]))
        last = self._est_ms
        dt = (ms - last) / 1000.0 if last is not None else 0.0
        self._est_steady = 0.0 < dt <= 1.0 and abs(h - self._est_hspeed) <= 1.0 * dt
        self._est_hspeed, self._est_ms = h, ms
        self._vel = v_enu

    def _new_sample(self, ms: int) -> None:
        """A new position sample: its own ``time_boot_ms`` (not the latest of all messages: ATTITUDE or SYSTEM_TIME
        stamped a few ms later may have come first), on the run's clock, stamps the odometry made from it, and
        :attr:`sample_key` changes. Caller holds ``_lock``."""
        raw = self._clock.sample_time(ms)
        self._pos_t = max(raw, self._pos_t)
        self._pos_seq += 1

    @property
    def sample_key(self) -> int:
        """Changes with every new position sample from the vehicle (GLOBAL_POSITION_INT, or LOCAL_POSITION_NED
        without a global position): the drone records odometry once per sample, never the same one again under a
        new timestamp (:meth:`odometry` is stamped with the sample's own vehicle time)."""
        return self._pos_seq

    def on_attitude(self, msg: Any) -> None:
        """ATTITUDE: roll, pitch (degrees) and ENU yaw. Caller holds ``_lock``."""
        self._boot_ms(msg.time_boot_ms)
        yaw = VehicleBackend.enu_yaw_from_heading(math.degrees(msg.yaw))
        self._att = (math.degrees(msg.roll), math.degrees(msg.pitch), yaw)
        self._att_wall = time.monotonic()

    def on_system_time(self, msg: Any) -> None:
        """SYSTEM_TIME: a ``time_boot_ms`` for the vehicle clock."""
        self._boot_ms(msg.time_boot_ms)

    def on_sys_status(self, msg: Any) -> None:
        """SYS_STATUS: sensor bits for readiness, the battery (when BATTERY_STATUS gives none) and its voltage."""
        self._sensors = (msg.onboard_control_sensors_present, msg.onboard_control_sensors_enabled,
                         msg.onboard_control_sensors_health)
        self._health_seen |= msg.onboard_control_sensors_health
        if msg.battery_remaining >= 0 and self._battery_from != "BATTERY_STATUS":
            self._battery = float(msg.battery_remaining)
            self._battery_from = "SYS_STATUS"
        if msg.voltage_battery not in (0, 65535):
            self._battery_v = msg.voltage_battery / 1000.0

    def on_battery_status(self, msg: Any) -> None:
        """BATTERY_STATUS of battery 0: remaining % and, without SYS_STATUS's, the voltage of its cells."""
        if msg.id != 0:
            return
        if msg.battery_remaining >= 0:
            self._battery = float(msg.battery_remaining)
            self._battery_from = "BATTERY_STATUS"
        cells = [v for v in msg.voltages if v not in (65535, 0)]
        if cells and not self._battery_v:
            self._battery_v = sum(cells) / 1000.0

    def on_gps_raw_int(self, msg: Any) -> None:
        """GPS_RAW_INT: the fix type, with a 3-D fix the receiver's horizontal accuracy (``h_acc`` mm, a MAVLink 2
        extension; 0 or absent: not reported) and the GNSS speed for the speed limits' margin."""
        self._gps_fix = msg.fix_type
        if msg.fix_type >= M.GPS_FIX_TYPE_3D_FIX:
            self._gps_h_acc = max(0.0, float(getattr(msg, "h_acc", 0) or 0) / 1000.0)
        if msg.fix_type >= M.GPS_FIX_TYPE_3D_FIX and msg.vel != 65535:  # UINT16_MAX: speed unknown
            for listener in self._gnss_listeners:
                listener.on_gnss_speed(msg.vel / 100.0, self._est_hspeed, self._est_steady)

    def on_extended_sys_state(self, msg: Any) -> None:
        """EXTENDED_SYS_STATE: the landed state (for :attr:`in_air`)."""
        self._landed_state = msg.landed_state
        self._landed_wall = time.monotonic()

    def on_home_position(self, msg: Any) -> None:
        """HOME_POSITION: the ENU origin until the first arming, and again while :meth:`arm` runs (the autopilot
        sets home where it arms). In flight a moved home (PX4 re-estimates it for minutes after take-off) and,
        after a flight, PX4's home moved to where it landed once disarmed (commander ``HomePosition::update``,
        ``hasMovedFromCurrentHomeLocation``) are only reported (``home_moved_in_flight``, ``home_moved``): the
        flight's positions keep their origin until the next arming. Caller holds ``_lock``."""
        home = GeoPoint(lat=msg.latitude / 1e7, lon=msg.longitude / 1e7, alt=msg.altitude / 1000.0)
        if self._home_after is not None and abs(home.lat - self._home_after.lat) <= 1e-7 \
                and abs(home.lon - self._home_after.lon) <= 1e-7 and abs(home.alt - self._home_after.alt) <= 0.01:
            return  # the moved home reported again (HOME_POSITION streams at 0.5 Hz)
        old = self.home
        moved = (not self._home_received or abs(home.lat - old.lat) > 1e-7 or abs(home.lon - old.lon) > 1e-7
                 or abs(home.alt - old.alt) > 0.01)
        if moved and self._home_received and self._link.armed:
            if abs(home.alt - old.alt) > abs(self._home_moved_alt - old.alt) + 0.5:  # a new largest move only
                self._home_moved_alt = home.alt
                self._event("home_moved_in_flight", lat=home.lat, lon=home.lon, alt=home.alt)
            return
        if moved and self._home_received and self._link.was_armed and not self.arming:
            self._event("home_moved", lat=home.lat, lon=home.lon, alt=home.alt, reason="after landing")
            self._home_after = home
            return
        if moved:
            self._rebase_home(home)

    def _boot_ms(self, ms: int) -> None:
        """A ``time_boot_ms`` for the vehicle clock; the events it reports are recorded. Caller holds ``_lock``."""
        for name in self._clock.on_boot_ms(ms):
            self._event(name)

    def home_for_flight(self) -> None:
        """A new flight (:meth:`arm`): a home the autopilot moved after the last flight (reported as ``home_moved``)
        becomes the ENU origin, as the home it sets where it arms will. Caller holds ``_lock``."""
        if self._home_after is not None and not self._link.armed:
            self._rebase_home(self._home_after)

    def readiness(self, system_status: int, ekf_using_gps: bool, ekf_report_unavailable: bool) -> Readiness:
        """The reports readiness is judged from (action.py :class:`Readiness`), with the link's: HEARTBEAT
        ``system_status``, ArduPilot's "EKFn IMUm is using GPS" seen, and whether EKF_STATUS_REPORT will never
        come. Caller holds ``_lock``."""
        present, health = (self._sensors[0], self._sensors[2]) if self._sensors is not None else (0, 0)
        return Readiness(gps_fix=self._gps_fix, home_received=self._home_received, sensors_present=present,
                         sensors_health=health, health_seen=self._health_seen, ekf_flags=self._ekf_flags,
                         system_status=system_status, armed=self._link.armed, ekf_using_gps=ekf_using_gps,
                         ekf_report_unavailable=ekf_report_unavailable)

    def _rebase_home(self, home: GeoPoint) -> None:
        """Make ``home`` the ENU origin (re-expressing the last fix in it). Caller holds ``_lock``."""
        self._home_moved_alt = home.alt
        self._home_after = None
        self.home = home
        self._home_received = True
        if self._geo is not None:
            e, n, _ = geodetic_to_enu(self._geo.lat, self._geo.lon, home.alt, home)
            self._pos = np.array([e, n, self._height()])
        self._event("home", lat=home.lat, lon=home.lon, alt=home.alt)

    @property
    def sys_status_seen(self) -> bool:
        """A SYS_STATUS has come (connect waits for the first)."""
        return self._sensors is not None

    def clear_odometry(self) -> None:
        """Forget the queued odometry (stamped on the clock before the connection's zero). Caller holds ``_lock``."""
        self._odom_q.clear()

    @property
    def position(self) -> np.ndarray:
        """(3,) ENU metres from home of the latest position sample (a copy)."""
        with self._lock:
            return self._pos.copy()

    @property
    def velocity(self) -> np.ndarray:
        """(3,) ENU m/s of the estimate (LOCAL_POSITION_NED, else GLOBAL_POSITION_INT), a copy."""
        with self._lock:
            return self._vel.copy()

    @property
    def attitude(self) -> tuple[float, float, float]:
        """Roll, pitch and ENU yaw in degrees (ATTITUDE; the yaw from GLOBAL_POSITION_INT ``hdg`` until one comes)."""
        return self._att

    @property
    def in_air(self) -> bool:
        """From EXTENDED_SYS_STATE's landed state when the autopilot sends it, else armed and above 0.3 m."""
        with self._lock:
            if self._landed_state and time.monotonic() - self._landed_wall < 5.0:
                return self._landed_state in (M.MAV_LANDED_STATE_IN_AIR, M.MAV_LANDED_STATE_TAKEOFF,
                                              M.MAV_LANDED_STATE_LANDING)
            return self._link.armed and self._height() > 0.3

    @property
    def battery_pct(self) -> float:
        """BATTERY_STATUS (battery 0) remaining %, else SYS_STATUS; 100 while the autopilot reports none."""
        b = self._battery
        return 100.0 if b is None else max(0.0, min(100.0, b))

    @property
    def gps_fix_type(self) -> int:
        """GPS_RAW_INT fix type (GPS_FIX_TYPE; 3 = 3-D), -1 before any report."""
        return self._gps_fix

    @property
    def gps_h_acc_m(self) -> float:
        """The receiver's horizontal accuracy (m) of the latest 3-D fix (GPS_RAW_INT ``h_acc``); 0: not reported."""
        return self._gps_h_acc

    @property
    def home_received(self) -> bool:
        """True once HOME_POSITION replaced the configured home as ENU origin."""
        return self._home_received

    def odometry(self) -> Odometry:
        """The latest position sample with the velocity, attitude, battery and state known with it, stamped with the
        sample's own vehicle time on the run's clock (never after the vehicle clock's :attr:`VehicleClock.t`)."""
        with self._lock:
            pos = tuple(float(v) for v in self._pos)
            geo = self._geo or enu_to_geodetic(pos[0], pos[1], pos[2], self.home)
            t = self._sample_run_t()
            return Odometry(robot_id=self.robot_id, t=t, position=pos, geodetic=geo,
                            velocity=tuple(float(v) for v in self._vel),
                            attitude=Attitude(roll=self._att[0], pitch=self._att[1], yaw=self._att[2]),
                            battery_pct=self.battery_pct, battery_voltage=self._battery_v, armed=self._link.armed,
                            in_air=self.in_air)

    def _sample_run_t(self) -> float:
        """The run time (s) of the position sample in ``_pos``: its own ``time_boot_ms`` mapped to the run's clock,
        never after the vehicle clock's :attr:`VehicleClock.t` (that time before the first sample). Caller holds ``_lock``."""
        t = self._clock.t
        if self._pos_seq:
            t = min(t, max(0.0, self._pos_t - self._clock.t_connect))
        return float(t)

    def pose_sample(self) -> PoseSample:
        """The latest position sample with the yaw known with it, stamped as :meth:`odometry` stamps it (the
        sample's own ``time_boot_ms`` on the run's clock, never after :attr:`VehicleClock.t`), read under one
        lock: see :meth:`~aerodaas.backends.base.VehicleBackend.pose_sample`."""
        with self._lock:
            return PoseSample(self._sample_run_t(), (float(self._pos[0]), float(self._pos[1]), float(self._pos[2])),
                              float(self._att[2]))

    def _queue_odometry(self) -> None:
        """Keep the odometry of the position sample just received (with the velocity, attitude and state known with
        it) for :meth:`drain_odometry`. Caller holds ``_lock``."""
        q = self._odom_q
        if self._odom_q_drained and len(q) == q.maxlen:
            self._odom_q_dropped += 1
        q.append(self.odometry())

    def drain_odometry(self, newest_only: bool = False) -> list[Odometry]:
        """See :meth:`~aerodaas.backends.base.VehicleBackend.drain_odometry`: every position sample received since the
        last call (at most :data:`ODOMETRY_QUEUE`; ``newest_only``: the newest), oldest first, each stamped with its
        own ``time_boot_ms`` on the run's clock. Samples pushed out of the full queue after a drain of every sample
        are reported in an ``odometry_samples_dropped`` event (``count``)."""
        with self._lock:
            out = list(self._odom_q)[-1:] if newest_only else list(self._odom_q)
            self._odom_q.clear()
            dropped = 0 if newest_only else self._odom_q_dropped
            self._odom_q_dropped, self._odom_q_drained = 0, True
        if dropped:
            self._event("odometry_samples_dropped", count=dropped)
        return out

