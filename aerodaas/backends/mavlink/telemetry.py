"""Telemetry: the state the autopilot streams (position, velocity, attitude, battery, GPS, landed state, home,
mission progress) and the :class:`~aerodaas.backends.base.VehicleBackend` state properties built from it."""
from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ...geo import enu_to_geodetic, geodetic_to_enu
from ...models import Attitude, GeoPoint, Odometry
from ._common import M, _enum_name, _f32, _log_level, log  # noqa: F401


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
        self._pos = np.array([e, n, self._rel_alt])
        self._has_global = True
        if time.monotonic() - self._local_wall > 1.0:  # no fresher LOCAL_POSITION_NED velocity
            self._vel = self.ned_to_enu((msg.vx / 100.0, msg.vy / 100.0, msg.vz / 100.0))
        if msg.hdg != 65535 and time.monotonic() - self._att_wall > 1.0:  # no ATTITUDE lately
            self._att = (self._att[0], self._att[1], self.enu_yaw_from_heading(msg.hdg / 100.0))

    def _on_local_position_ned(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)
        self._local_ned = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)
        self._local_wall = time.monotonic()
        self._vel = self.ned_to_enu((msg.vx, msg.vy, msg.vz))
        if not self._has_global:  # no global position (indoors): ENU from the EKF origin
            self._pos = self.ned_to_enu((msg.x, msg.y, msg.z))

    def _on_attitude(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)
        self._att = (math.degrees(msg.roll), math.degrees(msg.pitch), self.enu_yaw_from_heading(math.degrees(msg.yaw)))
        self._att_wall = time.monotonic()

    def _on_system_time(self, msg: Any) -> None:
        self._on_boot_ms(msg.time_boot_ms)

    def _on_sys_status(self, msg: Any) -> None:
        self._sensors = (msg.onboard_control_sensors_present, msg.onboard_control_sensors_enabled,
                         msg.onboard_control_sensors_health)
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

    def _on_extended_sys_state(self, msg: Any) -> None:
        self._landed_state = msg.landed_state
        self._landed_wall = time.monotonic()

    def _on_home_position(self, msg: Any) -> None:
        home = GeoPoint(lat=msg.latitude / 1e7, lon=msg.longitude / 1e7, alt=msg.altitude / 1000.0)
        old = self.home
        moved = (not self._home_received or abs(home.lat - old.lat) > 1e-7 or abs(home.lon - old.lon) > 1e-7
                 or abs(home.alt - old.alt) > 0.01)
        if moved:
            self.home = home
            self._home_received = True
            if self._geo is not None:  # re-express the last fix in the new frame
                e, n, _ = geodetic_to_enu(self._geo.lat, self._geo.lon, home.alt, home)
                self._pos = np.array([e, n, self._rel_alt])
            self._event("home", lat=home.lat, lon=home.lon, alt=home.alt)

    def _on_mission_current(self, msg: Any) -> None:
        if msg.seq != self._mission_seq:
            self._mission_seq = msg.seq
            self._event("mission_current", seq=msg.seq, item=self._item_number(msg.seq))

    def _item_number(self, wire_seq: int) -> int:
        """The :class:`MissionItem` ``seq`` (from 1, as :meth:`upload_mission` returns) of a wire sequence number:
        ArduPilot's wire numbering already starts at 1 (home is 0), PX4's at 0."""
        return wire_seq if self.autopilot == "ardupilot" else wire_seq + 1

    def _on_mission_item_reached(self, msg: Any) -> None:
        now = time.monotonic()
        if self._last_reached[0] == msg.seq and now - self._last_reached[1] < 1.0:
            return
        self._last_reached = (msg.seq, now)
        self._event("mission_item_reached", seq=msg.seq, item=self._item_number(msg.seq))

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
            return self._armed and self._rel_alt > 0.3

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
            return Odometry(robot_id=self.robot_id, t=self.t, position=pos, geodetic=geo,
                            velocity=tuple(float(v) for v in self._vel),
                            attitude=Attitude(roll=self._att[0], pitch=self._att[1], yaw=self._att[2]),
                            battery_pct=self.battery_pct, battery_voltage=self._battery_v, armed=self._armed,
                            in_air=self.in_air)

    def drain_events(self) -> list[dict[str, Any]]:
        out = []
        while self._events:
            try:
                out.append(self._events.popleft())
            except IndexError:
                break
        return out

    def _event(self, event: str, **fields: Any) -> None:
        self._events.append({"event": event, "t": round(self.t, 3), **fields})  # extrapolated while the link is down

