"""Flying the stored mission in AUTO / AUTO.MISSION: item sequencing, acceptance radius, hold, MISSION_ITEM_REACHED."""
from __future__ import annotations

import math
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.arming import Arming
from aerodaas.emulators.mavlink.flavour import PX4_REACHED_REPEATS
from aerodaas.emulators.mavlink.link import EmulatorLink
from aerodaas.emulators.mavlink.mission import MissionProtocol
from aerodaas.emulators.mavlink.modes import FlightModes
from aerodaas.emulators.mavlink.motion import Motion
from aerodaas.emulators.mavlink.state import EmulatorState, MissionStore

M = mavlink

__all__ = ["MissionRunner"]


class MissionRunner:
    """Runs the ``store``'s mission on ``state``: starts it (switching ``modes``, arming with ``arming`` on PX4),
    flies its items with ``motion``, makes the next one current through the mission ``protocol`` and reports
    MISSION_ITEM_REACHED and STATUSTEXT on ``link``. Not locked: the vehicle calls it under its lock."""

    def __init__(self, state: EmulatorState, store: MissionStore, link: EmulatorLink, modes: FlightModes,
                 motion: Motion, arming: Arming, protocol: MissionProtocol) -> None:
        self.state, self.store, self.link = state, store, link
        self.modes, self.motion, self.arming, self.protocol = modes, motion, arming, protocol
        self._reached_repeat: tuple[int, int, float] | None = None  # PX4: (seq, repeats left, next vehicle s)

    def mission_start(self, first: int) -> int:
        """MAV_CMD_MISSION_START (``first``: ArduPilot starts at that item when > 0): its MAV_RESULT. PX4 switches
        to AUTO.MISSION and arms; ArduPilot must be armed and switches to AUTO."""
        st = self.state
        s = st.veh.state
        if not self.store.nav_items():
            self.link.text(M.MAV_SEVERITY_CRITICAL, "Mission start denied! No valid mission")
            return M.MAV_RESULT_DENIED if st.px4 else M.MAV_RESULT_FAILED
        if st.px4:
            res = self.modes.request_mode("AUTO.MISSION")  # PX4 arms for MISSION_START itself
            if res == M.MAV_RESULT_ACCEPTED and not s.armed:
                res = self.arming.arm(False)
                if res == M.MAV_RESULT_ACCEPTED:
                    self.modes.begin_mission()
            return res
        if not s.armed:
            self.link.text(M.MAV_SEVERITY_WARNING, "Mission start failed: not armed")
            return M.MAV_RESULT_FAILED
        res = self.modes.request_mode("AUTO")
        if res != M.MAV_RESULT_ACCEPTED:
            return res
        if 0 < first < len(self.store.mission):
            self.protocol.set_current(first)
        self.modes.begin_mission()
        return M.MAV_RESULT_ACCEPTED

    def step(self) -> None:
        """Per physics step in AUTO / AUTO.MISSION: run DO_CHANGE_SPEED items, fly the current navigation item,
        end the mission past the last one."""
        st = self.state
        s = st.veh.state
        if self.store.run_state != "running" or not s.armed:
            return
        if st.px4 and st.takeoff_alt is not None and not self.store.starts_with_takeoff():
            return  # implicit PX4 take-off first
        while self.store.seq < len(self.store.mission):
            it = self.store.mission[self.store.seq]
            if not st.px4 and self.store.seq == 0:
                self.protocol.set_current(1)
                continue
            if it.command == M.MAV_CMD_DO_CHANGE_SPEED:
                if it.param2 > 0:
                    st.speed = float(it.param2)
                elif it.param2 == -2 and st.px4:  # ArduCopter's do_change_speed ignores speeds <= 0
                    st.speed = None
                self.motion.apply_speed_params()
                self._advance()
                continue
            break
        if self.store.seq >= len(self.store.mission):
            self._mission_done()
            return
        it = self.store.mission[self.store.seq]
        cmd = it.command
        if cmd in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LOITER_UNLIM):
            self._fly_item(it, cmd)
        elif cmd == M.MAV_CMD_NAV_TAKEOFF:
            alt = st.global_to_enu(st.origin.lat, st.origin.lon, it.z, it.frame)[2] - st.home_enu[2]
            if not self.store.item_started:
                self.store.item_started = True
                if st.rel()[2] < alt - 0.1:
                    self.motion.start_takeoff(alt)
            if st.takeoff_alt is None or abs(st.rel()[2] - alt) < 0.1:
                st.takeoff_alt = None
                self._item_done()
        elif cmd == M.MAV_CMD_NAV_LAND:
            if not self.store.item_started:
                self.store.item_started = True
                if not (it.x == 0 and it.y == 0):
                    st.phase = ""
                    land_target = st.global_to_enu(it.x / 1e7, it.y / 1e7, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT)
                    land_target[2] = s.position[2]
                    self.motion.goto_enu(land_target)
                else:
                    self.motion.start_land()
            if st.veh.setpoint.mode == "position" and math.hypot(*(st.veh.setpoint.target[0] - s.position[0],
                                                                    st.veh.setpoint.target[1] - s.position[1])) < 0.3:
                self.motion.start_land()
            if not s.in_air and st.took_off:
                self._item_done()
        elif cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self._item_done()
            self.modes.enter("AUTO.RTL" if st.px4 else "RTL")

    def _fly_item(self, it: Any, cmd: int) -> None:
        """NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_UNLIM: fly to the item (its target fixed when it starts; no
        position: where the vehicle is), arrive within the firmware's radius, hold param1 s, then done."""
        st = self.state
        s = st.veh.state
        if it.x == 0 and it.y == 0:
            g = st.geo()
            lat, lon = g.lat, g.lon
        else:
            lat, lon = it.x / 1e7, it.y / 1e7
        if not self.store.item_started:  # the target is fixed when the item starts (relative to home then)
            self.store.item_started = True
            self.store.item_target = st.global_to_enu(lat, lon, it.z, it.frame)
            self.motion.goto_enu(self.store.item_target)
            if not st.px4:  # AP_Mission start_command: "Mission: <index> <type>"
                self.link.text(M.MAV_SEVERITY_INFO, f"Mission: {self.store.seq} WP")
        target = self.store.item_target
        if st.px4:  # navigator: within the acceptance radius (NAV_ACC_RAD or the item's param2)
            radius = it.param2 if cmd == M.MAV_CMD_NAV_WAYPOINT and it.param2 > 0 else st.params["NAV_ACC_RAD"]
        else:  # AC_WPNav::reached_wp_destination: the S-curve has ended at the point (and within WPNAV_RADIUS)
            radius = min(0.3, st.params["WPNAV_RADIUS"] / 100.0)
        d_h = math.hypot(*(target[:2] - s.position[:2]))
        d_v = abs(target[2] - s.position[2])
        if self.store.item_reached_at is None and d_h <= radius and d_v <= 1.0:
            self.store.item_reached_at = st.t  # arrival: the hold (param1, s) starts
        if self.store.item_reached_at is not None:
            # both firmware send MISSION_ITEM_REACHED when the hold is over, then go on (ArduCopter/
            # mode_auto.cpp ModeAuto::verify_nav_wp / verify_loiter_time; PX4 src/modules/navigator/
            # mission_block.cpp is_mission_item_reached); LOITER_UNLIM is never reached
            hold = it.param1 if cmd in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME) else math.inf
            if st.t - self.store.item_reached_at >= max(0.0, hold):
                self._item_done()

    def _item_done(self) -> None:
        """The current item is complete: MISSION_ITEM_REACHED for it and the next item current. PX4 publishes both
        in one mission result and its MAVLink mission manager sends MISSION_CURRENT (the next item) before
        MISSION_ITEM_REACHED (MavlinkMissionManager::send, src/modules/mavlink/mavlink_mission.cpp); ArduPilot
        sends the reached report as the item completes, its MISSION_CURRENT at the stream rate."""
        st = self.state
        seq = self.store.seq
        if st.px4:
            self._advance()
            self._reached(seq)
        else:
            self._reached(seq)
            self._advance()

    def _reached(self, seq: int) -> None:
        """MISSION_ITEM_REACHED ``seq``: ArduPilot says "Reached command #N" with it; PX4 repeats it 10 times, once
        a vehicle second, until another item is reached (src/modules/mavlink/mavlink_mission.cpp)."""
        st = self.state
        self.store.reached_log.append(seq)
        self.link.send(self.link.enc.mission_item_reached_encode(seq))
        if st.px4:
            self._reached_repeat = (seq, PX4_REACHED_REPEATS, st.t + 1.0)
        else:
            self.link.text(M.MAV_SEVERITY_INFO, f"Reached command #{seq}")

    def repeat_reached_tick(self) -> None:
        """Per physics step: PX4's repeated MISSION_ITEM_REACHED, once a vehicle second."""
        st = self.state
        if self._reached_repeat is None:
            return
        seq, left, due = self._reached_repeat
        if st.t >= due:
            self.link.send(self.link.enc.mission_item_reached_encode(seq))
            self._reached_repeat = (seq, left - 1, st.t + 1.0) if left > 1 else None

    def _advance(self) -> None:
        if self.store.seq + 1 >= len(self.store.mission):  # past the last item: the mission ends (next step), and
            self.store.seq = len(self.store.mission)  # MISSION_CURRENT stays at the last item, as both firmware do
            self.store.item_started, self.store.item_reached_at = False, None
            return
        self.protocol.set_current(self.store.seq + 1)

    def _mission_done(self) -> None:
        st = self.state
        self.store.run_state = "done"
        self.link.text(M.MAV_SEVERITY_INFO, "Mission: complete" if not st.px4 else "Mission finished")
        self.store.seq = max(0, len(self.store.mission) - 1)
        if st.px4 and st.mode == "AUTO.MISSION" and st.veh.state.in_air:
            self.modes.enter("AUTO.LOITER")
        elif st.veh.state.in_air:
            st.veh.hold()
