"""Flying the stored mission in AUTO / AUTO.MISSION: item sequencing, acceptance radius, hold, MISSION_ITEM_REACHED."""
from __future__ import annotations

import math
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink



from aerodaas.emulators.mavlink.flavour import PX4_REACHED_REPEATS

M = mavlink


class MissionRunMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator` (state lives there)."""

    def _mission_start(self, first: int) -> int:
        s = self.veh.state
        if not self._mission_nav_items():
            self._text(M.MAV_SEVERITY_CRITICAL, "Mission start denied! No valid mission")
            return M.MAV_RESULT_DENIED if self.px4 else M.MAV_RESULT_FAILED
        if self.px4:
            res = self._request_mode("AUTO.MISSION")  # PX4 arms for MISSION_START itself
            if res == M.MAV_RESULT_ACCEPTED and not s.armed:
                res = self._arm(False)
                if res == M.MAV_RESULT_ACCEPTED:
                    self._begin_mission()
            return res
        if not s.armed:
            self._text(M.MAV_SEVERITY_WARNING, "Mission start failed: not armed")
            return M.MAV_RESULT_FAILED
        res = self._request_mode("AUTO")
        if res != M.MAV_RESULT_ACCEPTED:
            return res
        if 0 < first < len(self.mission):
            self._set_current(first)
        self._begin_mission()
        return M.MAV_RESULT_ACCEPTED

    def _mission_logic(self) -> None:
        s = self.veh.state
        if self.mission_state != "running" or not s.armed:
            return
        if self.px4 and self.takeoff_alt is not None and not self._starts_with_takeoff():
            return  # implicit PX4 take-off first
        while self.mission_seq < len(self.mission):
            it = self.mission[self.mission_seq]
            if not self.px4 and self.mission_seq == 0:
                self._set_current(1)
                continue
            if it.command == M.MAV_CMD_DO_CHANGE_SPEED:
                if it.param2 > 0:
                    self.speed = float(it.param2)
                elif it.param2 == -2 and self.px4:  # ArduCopter's do_change_speed ignores speeds <= 0
                    self.speed = None
                self._apply_speed_params()
                self._advance()
                continue
            break
        if self.mission_seq >= len(self.mission):
            self._mission_done()
            return
        it = self.mission[self.mission_seq]
        cmd = it.command
        if cmd in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LOITER_UNLIM):
            self._fly_item(it, cmd)
        elif cmd == M.MAV_CMD_NAV_TAKEOFF:
            alt = self._global_to_enu(self.origin.lat, self.origin.lon, it.z, it.frame)[2] - self.home_enu[2]
            if not self.item_started:
                self.item_started = True
                if self._rel()[2] < alt - 0.1:
                    self._start_takeoff(alt)
            if self.takeoff_alt is None or abs(self._rel()[2] - alt) < 0.1:
                self.takeoff_alt = None
                self._item_done()
        elif cmd == M.MAV_CMD_NAV_LAND:
            if not self.item_started:
                self.item_started = True
                if not (it.x == 0 and it.y == 0):
                    self.phase = ""
                    self._land_target = self._global_to_enu(it.x / 1e7, it.y / 1e7, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT)
                    self._land_target[2] = s.position[2]
                    self._goto_enu(self._land_target)
                else:
                    self._start_land()
            if self.veh.setpoint.mode == "position" and math.hypot(*(self.veh.setpoint.target[0] - s.position[0],
                                                                    self.veh.setpoint.target[1] - s.position[1])) < 0.3:
                self._start_land()
            if not s.in_air and self.took_off:
                self._item_done()
        elif cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self._item_done()
            self._enter("AUTO.RTL" if self.px4 else "RTL")

    def _fly_item(self, it: Any, cmd: int) -> None:
        """NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_UNLIM: fly to the item (its target fixed when it starts; no
        position: where the vehicle is), arrive within the firmware's radius, hold param1 s, then done."""
        s = self.veh.state
        if it.x == 0 and it.y == 0:
            g = self._geo()
            lat, lon = g.lat, g.lon
        else:
            lat, lon = it.x / 1e7, it.y / 1e7
        if not self.item_started:  # the target is fixed when the item starts (relative to home then)
            self.item_started = True
            self._item_target = self._global_to_enu(lat, lon, it.z, it.frame)
            self._goto_enu(self._item_target)
            if not self.px4:  # AP_Mission start_command: "Mission: <index> <type>"
                self._text(M.MAV_SEVERITY_INFO, f"Mission: {self.mission_seq} WP")
        target = self._item_target
        if self.px4:  # navigator: within the acceptance radius (NAV_ACC_RAD or the item's param2)
            radius = it.param2 if cmd == M.MAV_CMD_NAV_WAYPOINT and it.param2 > 0 else self.params["NAV_ACC_RAD"]
        else:  # AC_WPNav::reached_wp_destination: the S-curve has ended at the point (and within WPNAV_RADIUS)
            radius = min(0.3, self.params["WPNAV_RADIUS"] / 100.0)
        d_h = math.hypot(*(target[:2] - s.position[:2]))
        d_v = abs(target[2] - s.position[2])
        if self.item_reached_at is None and d_h <= radius and d_v <= 1.0:
            self.item_reached_at = self.t  # arrival: the hold (param1, s) starts
        if self.item_reached_at is not None:
            # both firmware send MISSION_ITEM_REACHED when the hold is over, then go on (ArduCopter/
            # mode_auto.cpp ModeAuto::verify_nav_wp / verify_loiter_time; PX4 src/modules/navigator/
            # mission_block.cpp is_mission_item_reached); LOITER_UNLIM is never reached
            hold = it.param1 if cmd in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME) else math.inf
            if self.t - self.item_reached_at >= max(0.0, hold):
                self._item_done()

    def _item_done(self) -> None:
        """The current item is complete: MISSION_ITEM_REACHED for it and the next item current. PX4 publishes both
        in one mission result and its MAVLink mission manager sends MISSION_CURRENT (the next item) before
        MISSION_ITEM_REACHED (MavlinkMissionManager::send, src/modules/mavlink/mavlink_mission.cpp); ArduPilot
        sends the reached report as the item completes, its MISSION_CURRENT at the stream rate."""
        seq = self.mission_seq
        if self.px4:
            self._advance()
            self._reached(seq)
        else:
            self._reached(seq)
            self._advance()

    def _reached(self, seq: int) -> None:
        """MISSION_ITEM_REACHED ``seq``: ArduPilot says "Reached command #N" with it; PX4 repeats it 10 times, once
        a vehicle second, until another item is reached (src/modules/mavlink/mavlink_mission.cpp)."""
        self.reached_log.append(seq)
        self._send(self._enc.mission_item_reached_encode(seq))
        if self.px4:
            self._reached_repeat = (seq, PX4_REACHED_REPEATS, self.t + 1.0)
        else:
            self._text(M.MAV_SEVERITY_INFO, f"Reached command #{seq}")

    def _repeat_reached(self) -> None:
        if self._reached_repeat is None:
            return
        seq, left, due = self._reached_repeat
        if self.t >= due:
            self._send(self._enc.mission_item_reached_encode(seq))
            self._reached_repeat = (seq, left - 1, self.t + 1.0) if left > 1 else None

    def _advance(self) -> None:
        if self.mission_seq + 1 >= len(self.mission):  # past the last item: the mission ends (next step), and
            self.mission_seq = len(self.mission)  # MISSION_CURRENT stays at the last item, as both firmware do
            self.item_started, self.item_reached_at = False, None
            return
        self._set_current(self.mission_seq + 1)

    def _mission_done(self) -> None:
        self.mission_state = "done"
        self._text(M.MAV_SEVERITY_INFO, "Mission: complete" if not self.px4 else "Mission finished")
        self.mission_seq = max(0, len(self.mission) - 1)
        if self.px4 and self.mode == "AUTO.MISSION" and self.veh.state.in_air:
            self._enter("AUTO.LOITER")
        elif self.veh.state.in_air:
            self.veh.hold()
