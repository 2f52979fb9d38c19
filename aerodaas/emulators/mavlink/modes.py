"""Flight modes: mode numbers to names, validation and entry of a mode as each firmware does it (ArduCopter
mode.cpp, PX4 commander mode requirements), the take-off command, and the RTL phases."""
from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.constants import (ARDUCOPTER_MODES, PX4_MODES, _AP_NEEDS_POSITION,
                                                 _PX4_NEEDS_POSITION)
from aerodaas.emulators.mavlink.link import EmulatorLink
from aerodaas.emulators.mavlink.motion import Motion
from aerodaas.emulators.mavlink.state import EmulatorState, MissionStore

M = mavlink

__all__ = ["FlightModes"]


class FlightModes:
    """The flight modes of the emulated firmware over ``state``: :meth:`request_mode` validates and
    :meth:`enter` switches, moving the vehicle with ``motion``, starting the ``store``'s mission, telling the ground
    stations on ``link`` why a mode is refused. Not locked: the vehicle calls it under its lock."""

    def __init__(self, state: EmulatorState, store: MissionStore, link: EmulatorLink, motion: Motion) -> None:
        self.state, self.store, self.link, self.motion = state, store, link, motion

    def mode_from_custom(self, custom_main: int, custom_sub: int = 0) -> str | None:
        """The mode named by HEARTBEAT/SET_MODE ``custom_mode`` (ArduCopter: the mode number; PX4: main and sub
        mode, sub 0 of AUTO meaning AUTO.MISSION), or None for an unknown one."""
        st = self.state
        if st.px4:
            for name, (m_, s_) in PX4_MODES.items():
                if m_ == custom_main and (s_ == custom_sub or (m_ != 4 and s_ == 0)):
                    return name
            if custom_main == 4 and custom_sub == 0:
                return "AUTO.MISSION"
            return None
        for name, num in ARDUCOPTER_MODES.items():
            if num == custom_main:
                return name
        return None

    def reject_mode(self, name: str, why: str) -> int:
        """Refuse mode ``name`` as the firmware does (its STATUSTEXT; ``why`` in ArduPilot's): the MAV_RESULT."""
        st = self.state
        if st.px4:
            self.link.text(M.MAV_SEVERITY_CRITICAL, f"Switching to {name} is currently not available")
            return M.MAV_RESULT_TEMPORARILY_REJECTED
        self.link.text(M.MAV_SEVERITY_WARNING, f"Mode change to {name} failed: {why}")
        return M.MAV_RESULT_FAILED

    def offboard_signal_back(self) -> None:
        """A setpoint arrived (PX4): in the offboard-loss fallback, the signal is back and PX4 ends its failsafe by
        itself, back to the pilot's OFFBOARD (the fallback lasts while ``offboard_control_signal_lost``,
        failsafe.cpp; PX4 SITL went RTL -> OFFBOARD 1 s after our stream resumed, 2026-11-24)."""
        st = self.state
        if st.px4 and st.offboard_fallback is not None:
            if st.mode == st.offboard_fallback and st.veh.state.armed:
                st.offboard_fallback = None
                self.link.text(M.MAV_SEVERITY_INFO, "Failsafe cleared: offboard control regained")
                self.enter("OFFBOARD")
            else:
                st.offboard_fallback = None

    def request_mode(self, name: str | None) -> int:
        """Validate and enter a mode; returns the MAV_RESULT. A commanded mode ends the offboard-loss fallback."""
        st = self.state
        st.offboard_fallback = None
        if name is None:
            if not st.px4:
                self.link.text(M.MAV_SEVERITY_WARNING, "Flight mode change failed")
            return M.MAV_RESULT_FAILED if not st.px4 else M.MAV_RESULT_TEMPORARILY_REJECTED
        s = st.veh.state
        # PX4 checks a mode's requirements always (commander ModeManagement / mode requirements); ArduCopter only
        # when armed (ArduCopter/mode.cpp Copter::set_mode: ignore_checks = !motors->armed())
        if st.px4 and name in _PX4_NEEDS_POSITION and not st.position_ok():
            return self.reject_mode(name, "requires position")
        if not st.px4 and name in _AP_NEEDS_POSITION and s.armed and not st.position_ok():
            return self.reject_mode(name, "requires position")
        if st.px4 and name == "OFFBOARD" and not st.offboard_stream_ok():
            return self.reject_mode(name, "no setpoint stream")
        if name in ("AUTO", "AUTO.MISSION"):
            if not self.store.nav_items():
                if st.px4:
                    self.link.text(M.MAV_SEVERITY_CRITICAL, "Mission start denied! No valid mission")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
                return self.reject_mode(name, "no mission")
            if not st.px4 and s.armed and not s.in_air and not self.store.starts_with_takeoff():
                self.link.text(M.MAV_SEVERITY_CRITICAL, "Auto: Missing Takeoff Cmd")
                return M.MAV_RESULT_FAILED
        self.enter(name)
        return M.MAV_RESULT_ACCEPTED

    def enter(self, name: str) -> None:
        """Switch to mode ``name`` (already validated) and start what it does: a mission, a landing, an RTL climb,
        a take-off, the last offboard target, or a hold."""
        st = self.state
        if name == st.mode and name not in ("AUTO", "AUTO.MISSION"):
            return
        s = st.veh.state
        prev = st.mode
        st.set_mode(name)
        st.phase = ""
        st.posvel = None
        st.velocity_deadline = None
        if name in ("AUTO", "AUTO.MISSION") and prev not in ("AUTO", "AUTO.MISSION"):
            if not st.px4 and s.armed and not s.in_air:
                self.store.run_state = "wait_start"  # ArduPilot: MAV_CMD_MISSION_START (or throttle) starts it
            else:
                self.begin_mission()
        if not s.armed or (not s.in_air and name not in ("AUTO.TAKEOFF", "AUTO", "AUTO.MISSION", "OFFBOARD")):
            if name in ("LAND", "AUTO.LAND", "RTL", "AUTO.RTL"):
                return
        if name in ("LAND", "AUTO.LAND"):
            if s.in_air:
                self.motion.start_land()
        elif name in ("RTL", "AUTO.RTL", "SMART_RTL"):
            if s.in_air:
                st.phase = "climb"
        elif name == "AUTO.TAKEOFF":
            if s.armed and not s.in_air:
                self.motion.start_takeoff(st.params["MIS_TAKEOFF_ALT"])
            elif s.in_air:
                st.veh.hold()
        elif name == "OFFBOARD" and st.last_target is not None:
            self.motion.fly_target(*st.last_target)
        elif name in ("GUIDED", "OFFBOARD"):
            if s.in_air and st.takeoff_alt is None:
                st.veh.hold()
        elif name in ("AUTO", "AUTO.MISSION"):
            pass
        else:  # LOITER, AUTO.LOITER, BRAKE, POSHOLD, manual modes without RC: hold position
            if s.in_air:
                st.veh.hold()

    def begin_mission(self) -> None:
        """Run the mission from the current item; PX4 on the ground takes off to MIS_TAKEOFF_ALT first unless
        the mission starts with a take-off item."""
        st = self.state
        s = st.veh.state
        self.store.item_started = False
        self.store.item_reached_at = None
        self.store.run_state = "running"
        if st.px4 and s.armed and not s.in_air and not self.store.starts_with_takeoff():
            self.motion.start_takeoff(st.params["MIS_TAKEOFF_ALT"])

    def rtl_step(self) -> None:
        """Per physics step in RTL (or an AUTO mission's return): climb to ``RTL_ALT`` (cm, ArduPilot) /
        ``RTL_RETURN_ALT`` (m, PX4) when lower, fly home, land."""
        st = self.state
        s = st.veh.state
        if not s.armed or not s.in_air:
            return
        rel = st.rel()
        rtl_alt = st.params["RTL_RETURN_ALT"] if st.px4 else st.params["RTL_ALT"] / 100.0
        if st.phase == "climb":
            alt = max(rtl_alt, rel[2])
            if rel[2] >= alt - 0.2:
                st.phase = "return"
                self.motion.goto_enu(np.array([st.home_enu[0], st.home_enu[1], st.home_enu[2] + rel[2]]))
            else:
                self.motion.goto_enu(np.array([s.position[0], s.position[1], st.home_enu[2] + alt]))
        elif st.phase == "return":
            if math.hypot(*(s.position[:2] - st.home_enu[:2])) < 0.5 and float(np.linalg.norm(s.velocity)) < 0.3:
                st.phase = "land"
                self.motion.start_land()

    def takeoff_command(self, p: list[float]) -> int:
        """MAV_CMD_NAV_TAKEOFF (``param7``: ArduPilot metres above home; PX4 metres AMSL, NaN: ``MIS_TAKEOFF_ALT``
        above home): its MAV_RESULT. ArduPilot needs GUIDED, armed, on the ground; PX4 switches to AUTO.TAKEOFF."""
        st = self.state
        s = st.veh.state
        if st.px4:
            if st.fix_type() < 3 or st.home is None:
                return self.reject_mode("AUTO.TAKEOFF", "requires position")
            alt_amsl = p[6]
            rel = st.params["MIS_TAKEOFF_ALT"] if alt_amsl != alt_amsl else alt_amsl - st.home.alt
            if st.mode != "AUTO.TAKEOFF":
                st.set_mode("AUTO.TAKEOFF")
            st.phase = ""
            if s.armed and not s.in_air:
                self.motion.start_takeoff(rel)
            return M.MAV_RESULT_ACCEPTED
        if st.mode != "GUIDED" or not s.armed or s.in_air:
            why = "not in GUIDED" if st.mode != "GUIDED" else "not armed" if not s.armed else "already flying"
            self.link.text(M.MAV_SEVERITY_WARNING, f"Takeoff refused: {why}")
            return M.MAV_RESULT_FAILED
        self.motion.start_takeoff(p[6])
        return M.MAV_RESULT_ACCEPTED
