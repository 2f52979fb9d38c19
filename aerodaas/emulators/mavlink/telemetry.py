"""Telemetry: the message streams (SET_MESSAGE_INTERVAL / REQUEST_DATA_STREAM rates, PX4's default set, the 1 Hz
HEARTBEAT) and the messages built from the vehicle state (mavlink.io common message set; what each flavour sends
is in :mod:`.vehicle`'s docstring)."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.camera import CameraHost
from aerodaas.emulators.mavlink.constants import _DATA_STREAMS, _PX4_DEFAULT_STREAMS, _STREAMABLE
from aerodaas.emulators.mavlink.flavour import EKF_STATUS_REPORT_ID
from aerodaas.emulators.mavlink.gimbal import EmulatedGimbal
from aerodaas.emulators.mavlink.link import EmulatorLink
from aerodaas.emulators.mavlink.state import EmulatorState, MissionStore
from aerodaas.missionfile.plan_ids import with_plan_id

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link

M = mavlink

__all__ = ["Telemetry"]

#: the messages :meth:`Telemetry._build_position` builds
_POSITION_MESSAGES = frozenset({M.MAVLINK_MSG_ID_GPS_RAW_INT, M.MAVLINK_MSG_ID_ATTITUDE,
                                M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                                M.MAVLINK_MSG_ID_HOME_POSITION})


class Telemetry:
    """The vehicle's telemetry over ``link``: :meth:`build` makes a message from ``state``, ``store`` (MISSION_CURRENT)
    and the ``gimbal``; :meth:`heartbeat_tick` and :meth:`interval_tick` stream them at the requested rates (vehicle
    time) with the ``camera``'s HEARTBEAT beside the autopilot's. ``message_interval``: False emulates firmware
    without MAV_CMD_SET_MESSAGE_INTERVAL (UNSUPPORTED). PX4 streams its default set from boot; ArduPilot nothing but
    HEARTBEAT until asked. Not locked: the vehicle calls it under its lock."""

    def __init__(self, state: EmulatorState, store: MissionStore, link: EmulatorLink, gimbal: EmulatedGimbal,
                 camera: CameraHost, message_interval: bool = True) -> None:
        self.state, self.store, self.link, self.gimbal, self.camera = state, store, link, gimbal, camera
        self._enc = link.enc
        self.message_interval_supported = message_interval
        #: message id -> interval in vehicle seconds
        self.intervals: dict[int, float] = (
            {m: 1.0 / hz for m, hz in _PX4_DEFAULT_STREAMS.items()} if state.px4 else {})
        self._next_due: dict[int, float] = {}
        self._next_hb = 0.0

    def heartbeat_tick(self) -> None:
        """Per physics step: HEARTBEAT once a vehicle second, with the attached camera component's own."""
        if self.state.t >= self._next_hb:
            self._next_hb = self.state.t + 1.0
            self.emit(M.MAVLINK_MSG_ID_HEARTBEAT)
            self.camera.heartbeat(self.link.peers)  # an attached camera component's own (camera.py)

    def interval_tick(self) -> None:
        """Per physics step: every streamed message that is due (never more than one per step each)."""
        t = self.state.t
        for mid, interval in list(self.intervals.items()):
            due = self._next_due.get(mid, 0.0)
            if t >= due:
                self._next_due[mid] = max(due + interval, t)
                self.emit(mid)

    def set_message_interval(self, p: list[float]) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL (param1 message id, param2 interval µs; -1 stops, 0 the default): its
        MAV_RESULT (DENIED for a message the vehicle cannot stream, UNSUPPORTED without the command)."""
        if not self.message_interval_supported:
            return M.MAV_RESULT_UNSUPPORTED
        msg_id, interval = int(p[0]), p[1]
        if msg_id not in _STREAMABLE:
            return M.MAV_RESULT_DENIED
        if interval == -1:
            self.intervals.pop(msg_id, None)
        elif interval == 0:
            default = _PX4_DEFAULT_STREAMS.get(msg_id) if self.state.px4 else None
            if default:
                self.intervals[msg_id] = 1.0 / default
            else:
                self.intervals.pop(msg_id, None)
        elif interval > 0:
            self.intervals[msg_id] = interval / 1e6  # µs -> vehicle seconds
            self._next_due[msg_id] = self.state.t
        else:
            return M.MAV_RESULT_DENIED
        return M.MAV_RESULT_ACCEPTED

    def on_request_data_stream(self, link: _Link, msg: Any) -> None:
        """REQUEST_DATA_STREAM (ArduPilot's legacy stream groups, GCS_Common.cpp): start or stop a group's messages
        at ``req_message_rate`` Hz; PX4 ignores it."""
        if self.state.px4 or msg.target_system not in (0, self.link.system_id):
            return  # PX4 does not implement the deprecated stream groups
        groups = list(_DATA_STREAMS) if msg.req_stream_id == M.MAV_DATA_STREAM_ALL else [msg.req_stream_id]
        for g in groups:
            for mid in _DATA_STREAMS.get(g, ()):
                if msg.start_stop and msg.req_message_rate > 0:
                    self.intervals[mid] = 1.0 / msg.req_message_rate
                    self._next_due[mid] = self.state.t
                else:
                    self.intervals.pop(mid, None)

    def emit(self, msg_id: int, link: _Link | None = None) -> None:
        """Send message ``msg_id`` (:meth:`build`) to ``link`` (None: every peer), if the vehicle has one to send."""
        msg = self.build(msg_id)
        if msg is not None:
            self.link.send(msg, link)

    def build(self, msg_id: int) -> Any | None:
        """The message ``msg_id`` for the current state, or None when the vehicle has none to send."""
        st = self.state
        boot_ms = st.boot_ms()
        fix = st.fix_type()
        if msg_id in _POSITION_MESSAGES:
            return self._build_position(msg_id, boot_ms, fix)
        gimbal = self.gimbal.build(msg_id, self._enc, boot_ms)  # GIMBAL_DEVICE_ATTITUDE_STATUS, _MANAGER_INFORMATION
        return gimbal if gimbal is not None else self._build_status(msg_id, boot_ms)

    def _build_position(self, msg_id: int, boot_ms: int, fix: int) -> Any | None:
        """GPS_RAW_INT, ATTITUDE, GLOBAL_POSITION_INT, LOCAL_POSITION_NED, HOME_POSITION (``fix``: the GPS fix
        type; without a 3D fix there is no position)."""
        st = self.state
        e, s = self._enc, st.veh.state
        if msg_id == M.MAVLINK_MSG_ID_GPS_RAW_INT:
            g = st.geo()
            v = float(np.hypot(s.velocity[0], s.velocity[1]))
            lat, lon = (int(round(g.lat * 1e7)), int(round(g.lon * 1e7))) if fix >= 3 else (0, 0)
            return e.gps_raw_int_encode(int(st.t * 1e6), fix, lat, lon, int(g.alt * 1000), 80 if fix >= 3 else 9999,
                                        120 if fix >= 3 else 9999, int(v * 100), 0, 12 if fix >= 3 else 3)
        if msg_id == M.MAVLINK_MSG_ID_ATTITUDE:
            return e.attitude_encode(boot_ms, 0.0, float(np.clip(s.velocity[1] * 0.05, -0.4, 0.4)),
                                     math.radians(st.heading()) if st.heading() <= 180 else
                                     math.radians(st.heading() - 360.0), 0.0, 0.0, 0.0)
        if msg_id == M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            if fix < 3:
                if st.px4:
                    return None
                return e.global_position_int_encode(boot_ms, 0, 0, 0, 0, 0, 0, 0, 65535)  # ArduPilot: stale zeros
            g, rel = st.geo(), st.rel()
            ve, vn, vu = st.estimated_velocity()
            vd = -vu
            return e.global_position_int_encode(boot_ms, int(round(g.lat * 1e7)), int(round(g.lon * 1e7)),
                                                int(round(g.alt * 1000)), int(round(rel[2] * 1000)), int(vn * 100),
                                                int(ve * 100), int(vd * 100), int(st.heading() * 100) % 36000)
        if msg_id == M.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            if fix < 3:
                return None
            p, v = s.position, st.estimated_velocity()
            return e.local_position_ned_encode(boot_ms, float(p[1]), float(p[0]), float(-p[2]), float(v[1]),
                                               float(v[0]), float(-v[2]))
        if msg_id == M.MAVLINK_MSG_ID_HOME_POSITION:
            if st.home is None:
                return None
            h = st.home
            hx = st.home_enu
            return e.home_position_encode(int(round(h.lat * 1e7)), int(round(h.lon * 1e7)), int(round(h.alt * 1000)),
                                          float(hx[1]), float(hx[0]), float(-hx[2]), [1, 0, 0, 0], 0, 0, 0,
                                          int(st.t * 1e6))
        return None

    def _build_status(self, msg_id: int, boot_ms: int) -> Any | None:
        """HEARTBEAT, SYS_STATUS, EKF_STATUS_REPORT, SYSTEM_TIME, EXTENDED_SYS_STATE, BATTERY_STATUS, MISSION_CURRENT,
        VFR_HUD, AUTOPILOT_VERSION."""
        st = self.state
        e, s = self._enc, st.veh.state
        if msg_id == M.MAVLINK_MSG_ID_HEARTBEAT:
            base, custom = st.mode_number()
            if st.px4:
                status = M.MAV_STATE_ACTIVE if s.armed else M.MAV_STATE_STANDBY
            else:
                status = M.MAV_STATE_ACTIVE if s.in_air else M.MAV_STATE_STANDBY
            ap = M.MAV_AUTOPILOT_PX4 if st.px4 else M.MAV_AUTOPILOT_ARDUPILOTMEGA
            return e.heartbeat_encode(M.MAV_TYPE_QUADROTOR, ap, base, custom, status, 3)
        if msg_id == M.MAVLINK_MSG_ID_SYS_STATUS:
            present, enabled, health = st.sensors()
            return e.sys_status_encode(present, enabled, health, 250, int(st.veh.battery_voltage * 1000), -1,
                                       int(round(st.veh.battery_pct)), 0, 0, 0, 0, 0, 0)
        if msg_id == EKF_STATUS_REPORT_ID:
            if st.px4:
                return None
            ok = st.position_ok()
            return e.ekf_status_report_encode(st.ekf_flags(), 0.1, 0.1 if ok else 1.0, 0.1, 0.1, 0.0)
        if msg_id == M.MAVLINK_MSG_ID_SYSTEM_TIME:
            return e.system_time_encode(int((1.7e9 + st.t) * 1e6), boot_ms)
        if msg_id == M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            if not s.in_air:
                landed = M.MAV_LANDED_STATE_ON_GROUND
            elif st.veh.setpoint.mode == "land":
                landed = M.MAV_LANDED_STATE_LANDING
            elif st.takeoff_alt is not None:
                landed = M.MAV_LANDED_STATE_TAKEOFF
            else:
                landed = M.MAV_LANDED_STATE_IN_AIR
            return e.extended_sys_state_encode(M.MAV_VTOL_STATE_UNDEFINED, landed)
        if msg_id == M.MAVLINK_MSG_ID_BATTERY_STATUS:
            mv = int(st.veh.battery_voltage * 1000)
            cells = [mv] + [65535] * 9
            return e.battery_status_encode(0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 32767, cells, -1, -1,
                                           -1, int(round(st.veh.battery_pct)))
        if msg_id == M.MAVLINK_MSG_ID_MISSION_CURRENT:
            # mission_state and mission_mode as the firmwares report them (mission.py reports_the_running_mission):
            # running in the mission mode ACTIVE; running in another mode PX4 PAUSED, ArduPilot NOT_STARTED (leaving
            # AUTO stops its mission); mission_mode 1 in the mission mode, else PX4 2 (suspended), ArduPilot 0
            store = self.store
            in_mission = st.mode in ("AUTO", "AUTO.MISSION")
            if not store.mission:
                state = M.MISSION_STATE_NO_MISSION
            elif store.run_state == "done":
                state = M.MISSION_STATE_COMPLETE
            elif store.run_state == "running" and in_mission:
                state = M.MISSION_STATE_ACTIVE
            elif store.run_state == "running" and st.px4:
                state = M.MISSION_STATE_PAUSED
            else:
                state = M.MISSION_STATE_NOT_STARTED
            current = e.mission_current_encode(min(store.seq, max(0, len(store.mission) - 1)), len(store.mission),
                                               state, 1 if in_mission else (2 if st.px4 else 0))
            plan_id = store.mission_id()  # PX4 reports its stored mission's id; ArduPilot none
            return with_plan_id(current, plan_id) if plan_id else current
        if msg_id == M.MAVLINK_MSG_ID_VFR_HUD:
            v = float(np.hypot(s.velocity[0], s.velocity[1]))
            return e.vfr_hud_encode(v, v, int(st.heading()), 50 if s.in_air else 0, float(st.geo().alt),
                                    float(s.velocity[2]))
        if msg_id == M.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            caps = (M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                    | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                    | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2)
            version = (1 << 24) | (15 << 16) if st.px4 else (4 << 24) | (5 << 16)
            return e.autopilot_version_encode(caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0)
        return None

