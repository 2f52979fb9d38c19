"""Telemetry: the state the autopilot streams (position, velocity, attitude, battery, GPS, landed state, home;
mission progress is the mission's, :mod:`.mission`) and the :class:`~aerodaas.backends.base.VehicleBackend` state
properties built from it."""
from __future__ import annotations

import math
import time
from collections import deque
from typing import Any

import numpy as np

from aerodaas.model.geo import enu_to_geodetic, geodetic_to_enu
from aerodaas.model.types import Attitude, GeoPoint, Odometry
from aerodaas.backends.mavlink.action import Readiness
from aerodaas.backends.mavlink._common import M, _enum_name, _f32, _log_level, log  # noqa: F401


#: position samples kept for :meth:`TelemetryMixin.drain_odometry` (60 vehicle seconds at the default 10 Hz stream;
#: the drone's clock thread drains them every step, so only a thread held up for that long loses any)
ODOMETRY_QUEUE = 600


class TelemetryMixin:
    """Part of :class:`~aerodaas.backends.mavlink.MavlinkBackend` (see its docstring for the shared state)."""

    def _on_global_position_int(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)
        if msg.lat == 0 and msg.lon == 0:
            return  # ArduPilot sends zeros before its position estimate exists
        lat, lon = msg.lat / 1e7, msg.lon / 1e7
        self._geo = GeoPoint(lat=lat, lon=lon, alt=msg.alt / 1000.0)
        self._rel_alt = msg.relative_alt / 1000.0
        e, n, _ = geodetic_to_enu(lat, lon, self.home.alt, self.home)
        self._pos = np.array([e, n, self._height()])
        self._new_sample(msg.time_boot_ms)
        self._has_global = True
        self.mission.on_position()
        if time.monotonic() - self._local_wall > 1.0:  # no fresher LOCAL_POSITION_NED velocity
            self._set_velocity(self.ned_to_enu((msg.vx / 100.0, msg.vy / 100.0, msg.vz / 100.0)), msg.time_boot_ms)
        if msg.hdg != 65535 and time.monotonic() - self._att_wall > 1.0:  # no ATTITUDE lately
            self._att = (self._att[0], self._att[1], self.enu_yaw_from_heading(msg.hdg / 100.0))
        self._queue_odometry()

    def _height(self) -> float:
        """Metres above the altitude reference (the take-off point's AMSL altitude, fixed at arming: a frame that
        does not move), else above home (``relative_alt``) before the first arming. Caller holds ``_lock``."""
        if self._alt_ref is not None and self._geo is not None:
            return self._geo.alt - self._alt_ref
        return self._rel_alt

    def _fix_altitude_reference(self) -> None:
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

    def _on_ekf_status_report(self, msg: Any) -> None:
        """ArduPilot EKF_STATUS_REPORT: ``flags`` (EKF_STATUS_FLAGS) for readiness."""
        self._ekf_flags = int(msg.flags)

    def _on_estimator_status(self, msg: Any) -> None:
        """PX4 ESTIMATOR_STATUS: ``flags`` (ESTIMATOR_STATUS_FLAGS) for readiness."""
        self._ekf_flags = int(msg.flags)

    def _on_local_position_ned(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)
        self._local_ned = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)
        self._local_wall = time.monotonic()
        self._set_velocity(self.ned_to_enu((msg.vx, msg.vy, msg.vz)), msg.time_boot_ms)
        if not self._has_global:  # no global position (indoors): ENU from the EKF origin
            self._pos = self.ned_to_enu((msg.x, msg.y, msg.z))
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
        raw = self._raw_t()
        if self._boot_ref is not None and self._boot_ref[0] <= ms:
            raw = self._boot_ref[1] + (ms - self._boot_ref[0]) / 1000.0
        self._pos_t = max(raw, self._pos_t)
        self._pos_seq += 1

    @property
    def sample_key(self) -> int:
        """Changes with every new position sample from the vehicle (GLOBAL_POSITION_INT, or LOCAL_POSITION_NED
        without a global position): the drone records odometry once per sample, never the same one again under a
        new timestamp (:meth:`odometry` is stamped with the sample's own vehicle time)."""
        return self._pos_seq

    def _on_attitude(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)
        self._att = (math.degrees(msg.roll), math.degrees(msg.pitch), self.enu_yaw_from_heading(math.degrees(msg.yaw)))
        self._att_wall = time.monotonic()

    def _on_system_time(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)

    def _on_sys_status(self, msg: Any) -> None:
        self._sensors = (msg.onboard_control_sensors_present, msg.onboard_control_sensors_enabled,
                         msg.onboard_control_sensors_health)
        self._health_seen |= msg.onboard_control_sensors_health
        if msg.battery_remaining >= 0 and self._battery_from != "BATTERY_STATUS":
            self._battery = float(msg.battery_remaining)
            self._battery_from = "SYS_STATUS"
        if msg.voltage_battery not in (0, 65535):
            self._battery_v = msg.voltage_battery / 1000.0

    _battery_from = ""

    def _on_battery_status(self, msg: Any) -> None:
        if msg.id != 0:
            return
        if msg.battery_remaining >= 0:
            self._battery = float(msg.battery_remaining)
            self._battery_from = "BATTERY_STATUS"
        cells = [v for v in msg.voltages if v not in (65535, 0)]
        if cells and not self._battery_v:
            self._battery_v = sum(cells) / 1000.0

    def _on_gps_raw_int(self, msg: Any) -> None:
        self._gps_fix = msg.fix_type
        if msg.fix_type >= M.GPS_FIX_TYPE_3D_FIX and msg.vel != 65535:  # UINT16_MAX: speed unknown
            self.speed_limits.on_gnss_speed(msg.vel / 100.0, self._est_hspeed, self._est_steady)

    def _on_extended_sys_state(self, msg: Any) -> None:
        self._landed_state = msg.landed_state
        self._landed_wall = time.monotonic()

    def _on_home_position(self, msg: Any) -> None:
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
        if moved and self._home_received and self._armed:
            if abs(home.alt - old.alt) > abs(self._home_moved_alt - old.alt) + 0.5:  # a new largest move only
                self._home_moved_alt = home.alt
                self._event("home_moved_in_flight", lat=home.lat, lon=home.lon, alt=home.alt)
            return
        if moved and self._home_received and self._was_armed and not self.actions.arming:
            self._event("home_moved", lat=home.lat, lon=home.lon, alt=home.alt, reason="after landing")
            self._home_after = home
            return
        if moved:
            self._rebase_home(home)

    def _home_for_flight(self) -> None:
        """A new flight (:meth:`arm`): a home the autopilot moved after the last flight (reported as ``home_moved``)
        becomes the ENU origin, as the home it sets where it arms will. Caller holds ``_lock``."""
        if self._home_after is not None and not self._armed:
            self._rebase_home(self._home_after)

    def _readiness(self) -> Readiness:
        """The reports readiness is judged from (action.py :class:`Readiness`). Caller holds ``_lock``."""
        present, health = (self._sensors[0], self._sensors[2]) if self._sensors is not None else (0, 0)
        return Readiness(gps_fix=self._gps_fix, home_received=self._home_received, sensors_present=present,
                         sensors_health=health, health_seen=self._health_seen, ekf_flags=self._ekf_flags,
                         system_status=self._system_status, armed=self._armed, ekf_using_gps=self._ekf_using_gps,
                         ekf_report_unavailable=M.MAVLINK_MSG_ID_EKF_STATUS_REPORT in self._streams_refused
                         or self._stream_legacy)

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
    def position(self) -> np.ndarray:
        with self._lock:
            return self._pos.copy()

    @property
    def velocity(self) -> np.ndarray:
        with self._lock:
            return self._vel.copy()

    @property
    def yaw(self) -> float:
        return self._att[2]

    @property
    def armed(self) -> bool:
        return self._armed

    @property
    def in_air(self) -> bool:
        """From EXTENDED_SYS_STATE's landed state when the autopilot sends it, else armed and above 0.3 m."""
        with self._lock:
            if self._landed_state and time.monotonic() - self._landed_wall < 5.0:
                return self._landed_state in (M.MAV_LANDED_STATE_IN_AIR, M.MAV_LANDED_STATE_TAKEOFF,
                                              M.MAV_LANDED_STATE_LANDING)
            return self._armed and self._height() > 0.3

    @property
    def battery_pct(self) -> float:
        """BATTERY_STATUS (battery 0) remaining %, else SYS_STATUS; 100 while the autopilot reports none."""
        b = self._battery
        return 100.0 if b is None else max(0.0, min(100.0, b))

    @property
    def link_ok(self) -> bool:
        return self._link_ok

    @property
    def mode(self) -> str:
        """The flight mode from the latest HEARTBEAT, in pymavlink's names (``GUIDED``, ``OFFBOARD``, ``LOITER``...)."""
        return self._mode

    @property
    def gps_fix_type(self) -> int:
        """GPS_RAW_INT fix type (GPS_FIX_TYPE; 3 = 3-D), -1 before any report."""
        return self._gps_fix

    @property
    def home_received(self) -> bool:
        """True once HOME_POSITION replaced the configured home as ENU origin."""
        return self._home_received

    @property
    def clock_ratio(self) -> float:
        """Vehicle seconds per wall second, estimated from ``time_boot_ms`` (1 for a real vehicle)."""
        return self._ratio

    def odometry(self) -> Odometry:
        with self._lock:
            pos = tuple(float(v) for v in self._pos)
            geo = self._geo or enu_to_geodetic(pos[0], pos[1], pos[2], self.home)
            t = self.t
            if self._pos_seq:  # the sample's own time (time_boot_ms mapped to the run's clock), never after now
                t = min(t, max(0.0, self._pos_t - self._t_connect))
            return Odometry(robot_id=self.robot_id, t=t, position=pos, geodetic=geo,
                            velocity=tuple(float(v) for v in self._vel),
                            attitude=Attitude(roll=self._att[0], pitch=self._att[1], yaw=self._att[2]),
                            battery_pct=self.battery_pct, battery_voltage=self._battery_v, armed=self._armed,
                            in_air=self.in_air)

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
                    self._failsafe_undelivered = max(0, self._failsafe_undelivered - 1)
        return out

    def _event(self, event: str, **fields: Any) -> None:
        self._events.append({"event": event, "t": round(self.t, 3), **fields})  # extrapolated while the link is down

    def _init_telemetry(self) -> None:
        """The telemetry state (guarded by ``_lock``): the vehicle's latest position, velocity, attitude, battery, GPS
        and home as its streams report them (mission progress: mission.py), the odometry queue and the event queue."""
        self._events: deque[dict[str, Any]] = deque(maxlen=2000)
        # state (guarded by _lock)
        self._pos = np.zeros(3)
        self._pos_t = 0.0  # vehicle time (raw clock, s) of the position sample in _pos (telemetry.py)
        self._pos_seq = 0  # position samples received
        #: the odometry of each position sample not yet drained (telemetry.py drain_odometry), oldest first
        self._odom_q: deque[Odometry] = deque(maxlen=ODOMETRY_QUEUE)
        self._odom_q_dropped = 0  # samples pushed out of the full queue since it was last drained
        self._odom_q_drained = False  # drained once: the run takes samples now, an overflow is a loss
        self._vel = np.zeros(3)
        self._est_hspeed = 0.0  # its horizontal speed, m/s (telemetry.py _set_velocity) ...
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
        self._gps_fix = -1
        self._sensors: tuple[int, int, int] | None = None
        self._home_received = False
        self._home_after: GeoPoint | None = None  # the autopilot's home after a flight, when it moved (reported)
        self._att_wall = 0.0
        self._ekf_flags: int | None = None  # EKF_STATUS_REPORT (ArduPilot) / ESTIMATOR_STATUS (PX4) flags
        self._health_seen = 0  # every SYS_STATUS health bit ever reported
        self._alt_ref: float | None = None  # AMSL metres of the take-off point (fixed at arming)
        self._home_moved_alt = 0.0
