"""The MAVLink command protocol (COMMAND_LONG / COMMAND_INT -> COMMAND_ACK; mavlink.io/en/services/command.html) and the legacy SET_MODE / REQUEST_DATA_STREAM messages."""
from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.constants import _DATA_STREAMS, _IN_PROGRESS_PERIOD_S, _PX4_DEFAULT_STREAMS, _STREAMABLE


from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link

M = mavlink


class CommandMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator` (state lives there)."""

    def reject_next(self, command: int, count: int = 1,
                    result: int = M.MAV_RESULT_TEMPORARILY_REJECTED) -> None:
        """Answer the next ``count`` COMMAND_LONG/COMMAND_INT ``command`` (MAV_CMD number) with ``result``
        (MAV_RESULT, default TEMPORARILY_REJECTED: "try again later") without carrying it out. Raises ValueError
        for count < 1 or MAV_RESULT_ACCEPTED / IN_PROGRESS (see ``ack_only_commands`` / ``in_progress_commands``)."""
        if count < 1 or result in (M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS, M.MAV_RESULT_ENUM_END) \
                or result not in M.enums["MAV_RESULT"]:
            raise ValueError(f"reject_next: count must be >= 1 and result a refusing MAV_RESULT, got {count!r}, "
                             f"{result!r}")
        with self._lock:
            self._rejections.setdefault(int(command), []).extend([int(result)] * int(count))

    def _on_command_long(self, link: _Link, msg: Any) -> None:
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
        self._command(link, msg, msg.command, p)

    def _on_command_int(self, link: _Link, msg: Any) -> None:
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.x / 1e7, msg.y / 1e7, msg.z]
        self._command(link, msg, msg.command, p, frame=msg.frame)

    def _command(self, link: _Link, msg: Any, cmd: int, p: list[float], frame: int | None = None) -> None:
        self.commands_seen.append(cmd)
        if cmd in self.ignore_commands:
            return
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if cmd in self.in_progress_commands:  # repeated by _stream until the end of time
            prev = self._in_progress.get(cmd)
            self._in_progress[cmd] = (link, *src, self.t + _IN_PROGRESS_PERIOD_S, prev[4] if prev else 0)
            result = M.MAV_RESULT_IN_PROGRESS
        elif self._rejections.get(cmd):
            result = self._rejections[cmd].pop(0)
            if result == M.MAV_RESULT_TEMPORARILY_REJECTED:
                self._text(M.MAV_SEVERITY_WARNING, "Command temporarily rejected: busy")
        elif cmd in self.ack_only_commands:
            result = M.MAV_RESULT_ACCEPTED
        else:
            result = self._execute(link, cmd, p, frame)
        if result is None:
            return
        self._send(self._enc.command_ack_encode(cmd, result, 0, 0, *src), link)

    def _execute(self, link: _Link, cmd: int, p: list[float], frame: int | None) -> int | None:
        """Run COMMAND_LONG/_INT ``cmd`` with params ``p``: its MAV_RESULT, or None when the answer was sent here
        (a requested message follows its ACK)."""
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            return self._arm_disarm(p)
        if cmd == M.MAV_CMD_DO_SET_MODE:
            if not int(p[0]) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                return M.MAV_RESULT_UNSUPPORTED if self.px4 else M.MAV_RESULT_FAILED
            return self._request_mode(self._mode_from_custom(int(p[1]), int(p[2])))
        if cmd == M.MAV_CMD_NAV_TAKEOFF:
            return self._takeoff_command(p)
        if cmd == M.MAV_CMD_NAV_LAND:
            return self._request_mode("AUTO.LAND" if self.px4 else "LAND")
        if cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self._request_mode("AUTO.RTL" if self.px4 else "RTL")
        if cmd == M.MAV_CMD_DO_CHANGE_SPEED:
            return self._change_speed(p)
        if cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._set_message_interval(p)
        if cmd in (M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_GET_HOME_POSITION, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = {M.MAV_CMD_GET_HOME_POSITION: M.MAVLINK_MSG_ID_HOME_POSITION,
                      M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: M.MAVLINK_MSG_ID_AUTOPILOT_VERSION}.get(cmd, int(p[0]))
            out = self._build(msg_id)
            if out is None:
                return M.MAV_RESULT_FAILED if msg_id == M.MAVLINK_MSG_ID_HOME_POSITION else M.MAV_RESULT_DENIED
            self._send(self._enc.command_ack_encode(cmd, M.MAV_RESULT_ACCEPTED, 0, 0, 0, 0), link)
            self._send(out, link)
            return None
        if cmd == M.MAV_CMD_MISSION_START:
            return self._mission_start(int(p[0]) if p[0] == p[0] else 0)
        if cmd == M.MAV_CMD_DO_SET_MISSION_CURRENT:
            seq = int(p[0])
            if not 0 <= seq < len(self.mission):
                return M.MAV_RESULT_DENIED
            self._set_current(seq)
            return M.MAV_RESULT_ACCEPTED
        rel = M.MAV_FRAME_GLOBAL_RELATIVE_ALT if frame is None else frame
        gimbal = self.gimbal.command(cmd, p, lambda lat, lon, alt: self._global_to_enu(lat, lon, alt, rel))
        return M.MAV_RESULT_UNSUPPORTED if gimbal is None else gimbal

    def _arm_disarm(self, p: list[float]) -> int:
        """MAV_CMD_COMPONENT_ARM_DISARM (param2 21196 forces): a disarm in the air, or on PX4 before its land
        detector confirmed the landing, is refused as the firmware refuses it."""
        s = self.veh.state
        force = int(round(p[1])) == 21196
        if p[0] >= 0.5:
            return self._arm(force)
        if s.armed and not force and self.px4 and not s.in_air and self.landed_at is not None and \
                self.t - self.landed_at < self.land_detect_s:  # PX4's land detector has not said landed yet
            self._text(M.MAV_SEVERITY_CRITICAL, "Disarming denied: not landed")
            return M.MAV_RESULT_TEMPORARILY_REJECTED
        if s.armed and s.in_air and not force:
            if self.px4:
                self._text(M.MAV_SEVERITY_CRITICAL, "Disarming denied: not landed")
                return M.MAV_RESULT_TEMPORARILY_REJECTED
            self._text(M.MAV_SEVERITY_CRITICAL, "Disarm: vehicle is flying")
            return M.MAV_RESULT_FAILED
        if s.armed:
            s.in_air = False
            self._disarm("external command")
        return M.MAV_RESULT_ACCEPTED

    def _change_speed(self, p: list[float]) -> int:
        """MAV_CMD_DO_CHANGE_SPEED (param1 speed type, param2 m/s)."""
        if self.deny_default_speed:
            # ArduCopter/GCS_MAVLink_Copter.cpp handle_MAV_CMD_DO_CHANGE_SPEED: a speed that is not positive
            # (-1 "no change", -2 "default") is DENIED; climb/descent speeds (param1 2/3) change those rates
            if not p[1] > 0 or int(p[0]) not in (0, 1, 2, 3):
                return M.MAV_RESULT_DENIED
            if int(p[0]) in (0, 1):
                self.speed = float(p[1])
        elif p[1] == -2:  # PX4 Navigator: -2 restores the default cruise speed
            self.speed = None
        elif p[1] > 0:
            self.speed = float(p[1])
        elif p[1] != -1:
            return M.MAV_RESULT_DENIED
        self._apply_speed_params()  # the leg being flown changes speed too
        return M.MAV_RESULT_ACCEPTED

    def _set_message_interval(self, p: list[float]) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL (param1 message id, param2 interval µs; -1 stops, 0 the default)."""
        if not self.message_interval_supported:
            return M.MAV_RESULT_UNSUPPORTED
        msg_id, interval = int(p[0]), p[1]
        if msg_id not in _STREAMABLE:
            return M.MAV_RESULT_DENIED
        if interval == -1:
            self._intervals.pop(msg_id, None)
        elif interval == 0:
            default = _PX4_DEFAULT_STREAMS.get(msg_id) if self.px4 else None
            if default:
                self._intervals[msg_id] = 1.0 / default
            else:
                self._intervals.pop(msg_id, None)
        elif interval > 0:
            self._intervals[msg_id] = interval / 1e6  # µs -> vehicle seconds
            self._next_due[msg_id] = self.t
        else:
            return M.MAV_RESULT_DENIED
        return M.MAV_RESULT_ACCEPTED

    def _takeoff_command(self, p: list[float]) -> int:
        s = self.veh.state
        if self.px4:
            if self._fix_type() < 3 or self.home is None:
                return self._reject_mode("AUTO.TAKEOFF", "requires position")
            alt_amsl = p[6]
            rel = self.params["MIS_TAKEOFF_ALT"] if alt_amsl != alt_amsl else alt_amsl - self.home.alt
            if self.mode != "AUTO.TAKEOFF":
                self.mode = "AUTO.TAKEOFF"
                self.mode_log.append((self.t, self.mode))
            self.phase = ""
            if s.armed and not s.in_air:
                self._start_takeoff(rel)
            return M.MAV_RESULT_ACCEPTED
        if self.mode != "GUIDED" or not s.armed or s.in_air:
            why = "not in GUIDED" if self.mode != "GUIDED" else "not armed" if not s.armed else "already flying"
            self._text(M.MAV_SEVERITY_WARNING, f"Takeoff refused: {why}")
            return M.MAV_RESULT_FAILED
        self._start_takeoff(p[6])
        return M.MAV_RESULT_ACCEPTED

    def _on_set_mode(self, link: _Link, msg: Any) -> None:
        if msg.target_system not in (0, self.system_id) or not msg.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return
        cm = msg.custom_mode
        if self.px4:
            self._request_mode(self._mode_from_custom((cm >> 16) & 0xFF, (cm >> 24) & 0xFF))
        else:
            self._request_mode(self._mode_from_custom(cm))

    def _on_request_data_stream(self, link: _Link, msg: Any) -> None:
        if self.px4 or msg.target_system not in (0, self.system_id):
            return  # PX4 does not implement the deprecated stream groups
        groups = list(_DATA_STREAMS) if msg.req_stream_id == M.MAV_DATA_STREAM_ALL else [msg.req_stream_id]
        for g in groups:
            for mid in _DATA_STREAMS.get(g, ()):
                if msg.start_stop and msg.req_message_rate > 0:
                    self._intervals[mid] = 1.0 / msg.req_message_rate
                    self._next_due[mid] = self.t
                else:
                    self._intervals.pop(mid, None)
