"""Telemetry: the message streams (SET_MESSAGE_INTERVAL / REQUEST_DATA_STREAM rates) and the messages built from the vehicle state; position frames and home."""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.model.geo import enu_to_geodetic, geodetic_to_enu
from aerodaas.model.types import GeoPoint
from aerodaas.emulators.mavlink.constants import _IN_PROGRESS_PERIOD_S, _PROTOCOL_RETRIES
from aerodaas.emulators.mavlink.flavour import EKF_STATUS_REPORT_ID


M = mavlink


#: the messages :meth:`TelemetryMixin._build_position` builds
_POSITION_MESSAGES = frozenset({M.MAVLINK_MSG_ID_GPS_RAW_INT, M.MAVLINK_MSG_ID_ATTITUDE,
                                M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                                M.MAVLINK_MSG_ID_HOME_POSITION})

class TelemetryMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator` (state lives there)."""

    def _stream(self) -> None:
        if self.t >= self._next_hb:
            self._next_hb = self.t + 1.0
            self._emit(M.MAVLINK_MSG_ID_HEARTBEAT)
            self.camera_host.heartbeat(self._links)  # an attached camera component's own (camera.py)
        for cmd, (link, sysid, compid, due, pct) in list(self._in_progress.items()):
            if link not in self._links:
                del self._in_progress[cmd]
            elif self.t >= due:  # COMMAND_ACK.progress creeps towards 99 %, never done
                pct = min(99, pct + 1)
                self._in_progress[cmd] = (link, sysid, compid, self.t + _IN_PROGRESS_PERIOD_S, pct)
                self._send(self._enc.command_ack_encode(cmd, M.MAV_RESULT_IN_PROGRESS, pct, 0, sysid, compid), link)
        self._repeat_reached()
        if self._transfer is not None and self.t > self._transfer.deadline:
            tr = self._transfer
            tr.retries += 1
            if tr.retries > _PROTOCOL_RETRIES or tr.link not in self._links:
                self._transfer = None
                self._mission_ack(tr.link, tr.sysid, tr.compid, M.MAV_MISSION_OPERATION_CANCELLED)
            else:
                self._request_next()
        for mid, interval in list(self._intervals.items()):
            due = self._next_due.get(mid, 0.0)
            if self.t >= due:
                self._next_due[mid] = max(due + interval, self.t)
                self._emit(mid)

    def _emit(self, msg_id: int) -> None:
        msg = self._build(msg_id)
        if msg is not None:
            self._send(msg)

    def _build(self, msg_id: int) -> Any | None:
        """The message ``msg_id`` for the current state, or None when the vehicle has none to send."""
        boot_ms = int(self.boot_ms0 + self.t * 1000.0) & 0xFFFFFFFF
        fix = self._fix_type()
        if msg_id in _POSITION_MESSAGES:
            return self._build_position(msg_id, boot_ms, fix)
        gimbal = self.gimbal.build(msg_id, self._enc, boot_ms)  # GIMBAL_DEVICE_ATTITUDE_STATUS, _MANAGER_INFORMATION
        return gimbal if gimbal is not None else self._build_status(msg_id, boot_ms)

    def _build_position(self, msg_id: int, boot_ms: int, fix: int) -> Any | None:
        """GPS_RAW_INT, ATTITUDE, GLOBAL_POSITION_INT, LOCAL_POSITION_NED, HOME_POSITION (``fix``: the GPS fix
        type; without a 3D fix there is no position)."""
        e, s = self._enc, self.veh.state
        if msg_id == M.MAVLINK_MSG_ID_GPS_RAW_INT:
            g = self._geo()
            v = float(np.hypot(s.velocity[0], s.velocity[1]))
            lat, lon = (int(round(g.lat * 1e7)), int(round(g.lon * 1e7))) if fix >= 3 else (0, 0)
            return e.gps_raw_int_encode(int(self.t * 1e6), fix, lat, lon, int(g.alt * 1000), 80 if fix >= 3 else 9999,
                                        120 if fix >= 3 else 9999, int(v * 100), 0, 12 if fix >= 3 else 3)
        if msg_id == M.MAVLINK_MSG_ID_ATTITUDE:
            return e.attitude_encode(boot_ms, 0.0, float(np.clip(s.velocity[1] * 0.05, -0.4, 0.4)),
                                     math.radians(self._heading()) if self._heading() <= 180 else
                                     math.radians(self._heading() - 360.0), 0.0, 0.0, 0.0)
        if msg_id == M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            if fix < 3:
                if self.px4:
                    return None
                return e.global_position_int_encode(boot_ms, 0, 0, 0, 0, 0, 0, 0, 65535)  # ArduPilot: stale zeros
            g, rel = self._geo(), self._rel()
            ve, vn, vu = self._estimated_velocity()
            vd = -vu
            return e.global_position_int_encode(boot_ms, int(round(g.lat * 1e7)), int(round(g.lon * 1e7)),
                                                int(round(g.alt * 1000)), int(round(rel[2] * 1000)), int(vn * 100),
                                                int(ve * 100), int(vd * 100), int(self._heading() * 100) % 36000)
        if msg_id == M.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            if fix < 3:
                return None
            p, v = s.position, self._estimated_velocity()
            return e.local_position_ned_encode(boot_ms, float(p[1]), float(p[0]), float(-p[2]), float(v[1]),
                                               float(v[0]), float(-v[2]))
        if msg_id == M.MAVLINK_MSG_ID_HOME_POSITION:
            if self.home is None:
                return None
            h = self.home
            hx = self.home_enu
            return e.home_position_encode(int(round(h.lat * 1e7)), int(round(h.lon * 1e7)), int(round(h.alt * 1000)),
                                          float(hx[1]), float(hx[0]), float(-hx[2]), [1, 0, 0, 0], 0, 0, 0,
                                          int(self.t * 1e6))
        return None

    def _build_status(self, msg_id: int, boot_ms: int) -> Any | None:
        """HEARTBEAT, SYS_STATUS, EKF_STATUS_REPORT, SYSTEM_TIME, EXTENDED_SYS_STATE, BATTERY_STATUS, MISSION_CURRENT,
        VFR_HUD, AUTOPILOT_VERSION."""
        e, s = self._enc, self.veh.state
        if msg_id == M.MAVLINK_MSG_ID_HEARTBEAT:
            base, custom = self._mode_number()
            if self.px4:
                status = M.MAV_STATE_ACTIVE if s.armed else M.MAV_STATE_STANDBY
            else:
                status = M.MAV_STATE_ACTIVE if s.in_air else M.MAV_STATE_STANDBY
            ap = M.MAV_AUTOPILOT_PX4 if self.px4 else M.MAV_AUTOPILOT_ARDUPILOTMEGA
            return e.heartbeat_encode(M.MAV_TYPE_QUADROTOR, ap, base, custom, status, 3)
        if msg_id == M.MAVLINK_MSG_ID_SYS_STATUS:
            present, enabled, health = self._sensors()
            return e.sys_status_encode(present, enabled, health, 250, int(self.veh.battery_voltage * 1000), -1,
                                       int(round(self.veh.battery_pct)), 0, 0, 0, 0, 0, 0)
        if msg_id == EKF_STATUS_REPORT_ID:
            if self.px4:
                return None
            ok = self._position_ok()
            return e.ekf_status_report_encode(self._ekf_flags(), 0.1, 0.1 if ok else 1.0, 0.1, 0.1, 0.0)
        if msg_id == M.MAVLINK_MSG_ID_SYSTEM_TIME:
            return e.system_time_encode(int((1.7e9 + self.t) * 1e6), boot_ms)
        if msg_id == M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            if not s.in_air:
                landed = M.MAV_LANDED_STATE_ON_GROUND
            elif self.veh.setpoint.mode == "land":
                landed = M.MAV_LANDED_STATE_LANDING
            elif self.takeoff_alt is not None:
                landed = M.MAV_LANDED_STATE_TAKEOFF
            else:
                landed = M.MAV_LANDED_STATE_IN_AIR
            return e.extended_sys_state_encode(M.MAV_VTOL_STATE_UNDEFINED, landed)
        if msg_id == M.MAVLINK_MSG_ID_BATTERY_STATUS:
            mv = int(self.veh.battery_voltage * 1000)
            cells = [mv] + [65535] * 9
            return e.battery_status_encode(0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 32767, cells, -1, -1,
                                           -1, int(round(self.veh.battery_pct)))
        if msg_id == M.MAVLINK_MSG_ID_MISSION_CURRENT:
            return e.mission_current_encode(min(self.mission_seq, max(0, len(self.mission) - 1)), len(self.mission),
                                            0, 0)
        if msg_id == M.MAVLINK_MSG_ID_VFR_HUD:
            v = float(np.hypot(s.velocity[0], s.velocity[1]))
            return e.vfr_hud_encode(v, v, int(self._heading()), 50 if s.in_air else 0, float(self._geo().alt),
                                    float(s.velocity[2]))
        if msg_id == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            caps = (M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                    | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                    | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2)
            version = (1 << 24) | (15 << 16) if self.px4 else (4 << 24) | (5 << 16)
            return e.autopilot_version_encode(caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0)
        return None

    def _estimated_velocity(self) -> np.ndarray:
        """The velocity the estimator reports (ENU m/s): the true one with its horizontal speed lowered by
        ``estimate_speed_error_mps`` (GPS_RAW_INT keeps the true speed)."""
        v = np.array(self.veh.state.velocity, dtype=float)
        err = self.estimate_speed_error_mps
        h = float(np.hypot(v[0], v[1]))
        if err > 0 and h > 0:
            v[:2] *= max(0.0, h - err) / h
        return v

    def _heading(self) -> float:
        """Compass heading in degrees (clockwise from north) from the simulator's ENU yaw."""
        return (90.0 - self.veh.state.yaw) % 360.0

    def _fix_type(self) -> int:
        return M.GPS_FIX_TYPE_3D_FIX if self.t >= self.gps_lock_s else M.GPS_FIX_TYPE_NO_FIX

    def _geo(self) -> GeoPoint:
        p = self.veh.state.position
        return enu_to_geodetic(float(p[0]), float(p[1]), float(p[2]), self.origin)

    def _rel(self) -> np.ndarray:
        return self.veh.state.position - self.home_enu

    def _set_home_here(self) -> None:
        p = self.veh.state.position.copy()
        p[2] = min(p[2], 0.0) if not self.veh.state.in_air else p[2]
        self.home_enu = p
        self.home = enu_to_geodetic(float(p[0]), float(p[1]), float(p[2]), self.origin)
        self._emit(M.MAVLINK_MSG_ID_HOME_POSITION)

    def _global_to_enu(self, lat: float, lon: float, alt: float, frame: int) -> np.ndarray:
        """Global position (deg, deg, m in ``frame``) -> ENU metres in the simulator's (EKF origin) frame."""
        e, n, _ = geodetic_to_enu(lat, lon, self.origin.alt, self.origin)
        home_alt = self.home.alt if self.home is not None else self.origin.alt
        if frame in (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT):
            up = alt - self.origin.alt
        else:  # relative to home
            up = alt + (home_alt - self.origin.alt)
        return np.array([e, n, up])
