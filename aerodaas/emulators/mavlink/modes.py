"""Flight modes and the autopilot logic that runs every physics step: mode validation and entry, RTL phases, take-off completion, auto-disarm."""
from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.flavour import AIRFRAME_MAX_SPEED, PX4_HOME_MOVED_M
from aerodaas.emulators.mavlink.constants import ARDUCOPTER_MODES, PX4_MODES, _AP_NEEDS_POSITION, _PX4_MANUAL, _PX4_NEEDS_POSITION


M = mavlink


class ModeMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator` (state lives there)."""

    def _mode_number(self) -> tuple[int, int]:
        """(base_mode, custom_mode) for HEARTBEAT."""
        s = self.veh.state
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if s.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        if self.px4:
            main, sub = PX4_MODES[self.mode]
            if self.mode in _PX4_MANUAL:
                base |= M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
            else:
                base |= M.MAV_MODE_FLAG_AUTO_ENABLED | M.MAV_MODE_FLAG_GUIDED_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
            return base, (main << 16) | (sub << 24)
        base |= M.MAV_MODE_FLAG_STABILIZE_ENABLED | M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if self.mode in ("AUTO", "RTL", "LOITER", "GUIDED", "CIRCLE", "POSHOLD", "BRAKE", "SMART_RTL"):
            base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        return base, ARDUCOPTER_MODES[self.mode]

    def _mode_from_custom(self, custom_main: int, custom_sub: int = 0) -> str | None:
        if self.px4:
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

    def _reject_mode(self, name: str, why: str) -> int:
        if self.px4:
            self._text(M.MAV_SEVERITY_CRITICAL, f"Switching to {name} is currently not available")
            return M.MAV_RESULT_TEMPORARILY_REJECTED
        self._text(M.MAV_SEVERITY_WARNING, f"Mode change to {name} failed: {why}")
        return M.MAV_RESULT_FAILED

    def _offboard_signal_back(self) -> None:
        """A setpoint arrived (PX4): in the offboard-loss fallback, the signal is back and PX4 ends its failsafe by
        itself, back to the pilot's OFFBOARD (the fallback lasts while ``offboard_control_signal_lost``,
        failsafe.cpp; PX4 SITL went RTL -> OFFBOARD 1 s after our stream resumed, 2026-11-24)."""
        if self.px4 and self.offboard_fallback is not None:
            if self.mode == self.offboard_fallback and self.veh.state.armed:
                self.offboard_fallback = None
                self._text(M.MAV_SEVERITY_INFO, "Failsafe cleared: offboard control regained")
                self._enter("OFFBOARD")
            else:
                self.offboard_fallback = None

    def _request_mode(self, name: str | None) -> int:
        """Validate and enter a mode; returns the MAV_RESULT. A commanded mode ends the offboard-loss fallback."""
        self.offboard_fallback = None
        if name is None:
            if not self.px4:
                self._text(M.MAV_SEVERITY_WARNING, "Flight mode change failed")
            return M.MAV_RESULT_FAILED if not self.px4 else M.MAV_RESULT_TEMPORARILY_REJECTED
        s = self.veh.state
        # PX4 checks a mode's requirements always (commander ModeManagement / mode requirements); ArduCopter only
        # when armed (ArduCopter/mode.cpp Copter::set_mode: ignore_checks = !motors->armed())
        if self.px4 and name in _PX4_NEEDS_POSITION and not self._position_ok():
            return self._reject_mode(name, "requires position")
        if not self.px4 and name in _AP_NEEDS_POSITION and s.armed and not self._position_ok():
            return self._reject_mode(name, "requires position")
        if self.px4 and name == "OFFBOARD" and not self._offboard_stream_ok():
            return self._reject_mode(name, "no setpoint stream")
        if name in ("AUTO", "AUTO.MISSION"):
            if not self._mission_nav_items():
                if self.px4:
                    self._text(M.MAV_SEVERITY_CRITICAL, "Mission start denied! No valid mission")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
                return self._reject_mode(name, "no mission")
            if not self.px4 and s.armed and not s.in_air and not self._starts_with_takeoff():
                self._text(M.MAV_SEVERITY_CRITICAL, "Auto: Missing Takeoff Cmd")
                return M.MAV_RESULT_FAILED
        self._enter(name)
        return M.MAV_RESULT_ACCEPTED

    def _offboard_stream_ok(self) -> bool:
        """PX4 enters OFFBOARD only with a live setpoint stream: the last one within COM_OF_LOSS_T and at least
        two in the last vehicle second."""
        log = self.setpoint_log
        recent = len(log) >= 2 and self.t - log[-2] <= 1.0
        return self.t - self.last_setpoint_t <= self.params["COM_OF_LOSS_T"] and recent

    def _enter(self, name: str) -> None:
        if name == self.mode and name not in ("AUTO", "AUTO.MISSION"):
            return
        s = self.veh.state
        prev = self.mode
        self.mode = name
        self.mode_log.append((self.t, name))
        self.phase = ""
        self.posvel = None
        self.velocity_deadline = None
        if name in ("AUTO", "AUTO.MISSION") and prev not in ("AUTO", "AUTO.MISSION"):
            if not self.px4 and s.armed and not s.in_air:
                self.mission_state = "wait_start"  # ArduPilot: MAV_CMD_MISSION_START (or throttle) starts it
            else:
                self._begin_mission()
        if not s.armed or (not s.in_air and name not in ("AUTO.TAKEOFF", "AUTO", "AUTO.MISSION", "OFFBOARD")):
            if name in ("LAND", "AUTO.LAND", "RTL", "AUTO.RTL"):
                return
        if name in ("LAND", "AUTO.LAND"):
            if s.in_air:
                self._start_land()
        elif name in ("RTL", "AUTO.RTL", "SMART_RTL"):
            if s.in_air:
                self.phase = "climb"
        elif name == "AUTO.TAKEOFF":
            if s.armed and not s.in_air:
                self._start_takeoff(self.params["MIS_TAKEOFF_ALT"])
            elif s.in_air:
                self.veh.hold()
        elif name == "OFFBOARD" and self._last_target is not None:
            self._apply_target(*self._last_target, note=False)
        elif name in ("GUIDED", "OFFBOARD"):
            if s.in_air and self.takeoff_alt is None:
                self.veh.hold()
        elif name in ("AUTO", "AUTO.MISSION"):
            pass
        else:  # LOITER, AUTO.LOITER, BRAKE, POSHOLD, manual modes without RC: hold position
            if s.in_air:
                self.veh.hold()

    def _begin_mission(self) -> None:
        """Run the mission from the current item; PX4 on the ground takes off to MIS_TAKEOFF_ALT first unless
        the mission starts with a take-off item."""
        s = self.veh.state
        self.item_started = False
        self.item_reached_at = None
        self.mission_state = "running"
        if self.px4 and s.armed and not s.in_air and not self._starts_with_takeoff():
            self._start_takeoff(self.params["MIS_TAKEOFF_ALT"])

    def _start_takeoff(self, rel_alt: float) -> None:
        s = self.veh.state
        self.takeoff_alt = float(rel_alt)
        self._goto_enu(np.array([s.position[0], s.position[1], self.home_enu[2] + self.takeoff_alt]))

    def _autopilot_logic(self) -> None:
        s = self.veh.state
        mode = self.mode
        # auto-disarm: on the ground after arming without a take-off, and after landing
        if s.armed and not s.in_air:
            delay = self.params["COM_DISARM_PRFLT" if self.px4 else "DISARM_DELAY"]
            if not self.took_off and delay > 0 and self.t - self.armed_at > delay and not self._climbing():
                self._disarm("auto disarm (no take-off)")
            elif self.took_off and self.landed_at is not None:
                after = self.params["COM_DISARM_LAND"] if self.px4 else 1.0
                if after >= 0 and self.t - self.landed_at > after:  # PX4: COM_DISARM_LAND -1 disables it
                    self._disarm("landed")
                    if self.px4 and mode in ("AUTO.RTL", "AUTO.LAND"):
                        self._enter("AUTO.LOITER")  # PX4 SIH shows Hold once disarmed after an RTL/LAND (trace)
        if self.posvel is not None:
            if mode in ("GUIDED", "OFFBOARD") and s.armed and s.in_air:
                self._track_posvel()
            else:
                self.posvel = None
        # ArduPilot GUIDED velocity targets time out after 3 s
        if self.velocity_deadline is not None and self.t > self.velocity_deadline:
            self.velocity_deadline = None
            if s.in_air:
                self.veh.hold()
        # PX4 offboard loss: a mode fallback (commander/failsafe/failsafe.cpp checkModeFallback, COM_OBL_RC_ACT).
        # With the default parameters and no RC, PX4 SITL returns (AUTO.RTL; firmware trace of 2026-11-24). The
        # pilot's mode stays OFFBOARD: when setpoints come again the fallback ends (see _offboard_signal_back)
        if self.px4 and mode == "OFFBOARD" and self.t - self.last_setpoint_t > self.params["COM_OF_LOSS_T"]:
            self._text(M.MAV_SEVERITY_WARNING, "Failsafe activated: offboard control lost, returning")
            self._enter("AUTO.RTL")
            self.offboard_fallback = "AUTO.RTL"
        # take-off completion
        if self.takeoff_alt is not None and s.armed:
            if abs(self._rel()[2] - self.takeoff_alt) < 0.1:
                self.takeoff_alt = None
                if self.px4 and mode == "AUTO.TAKEOFF":
                    self._enter("AUTO.LOITER")
        if mode in ("RTL", "AUTO.RTL") or (mode in ("AUTO", "AUTO.MISSION") and self.phase):
            self._rtl_logic()
        elif mode in ("AUTO", "AUTO.MISSION"):
            self._mission_logic()

    def _climbing(self) -> bool:
        return self.takeoff_alt is not None or self.mission_state == "running"

    def _disarm(self, why: str) -> None:
        s = self.veh.state
        s.armed = False
        s.velocity[:] = 0.0
        self.veh.setpoint.mode = "idle"
        self.takeoff_alt = None
        self.phase = ""
        self.landed_at = None
        self._text(M.MAV_SEVERITY_INFO, f"Disarming motors ({why})" if not self.px4 else f"Disarmed by {why}")
        if self.px4 and self.home_enu is not None and self.params.get("COM_HOME_EN", 1.0) >= 0.5 \
                and math.hypot(*(s.position[:2] - self.home_enu[:2])) > PX4_HOME_MOVED_M:
            # PX4 commander, disarmed and landed: home follows the vehicle once it moved from it by more than
            # twice the GPS eph (HomePosition::update, hasMovedFromCurrentHomeLocation; SIH GPS eph 0.9 m)
            self._set_home_here()

    def _land_speed(self) -> float:
        return self.params["MPC_LAND_SPEED"] if self.px4 else self.params["LAND_SPEED"] / 100.0

    def _start_land(self) -> None:
        self.veh.land()
        self.veh.setpoint.land_speed = self._land_speed()
        self.takeoff_alt = None

    def _rtl_logic(self) -> None:
        s = self.veh.state
        if not s.armed or not s.in_air:
            return
        rel = self._rel()
        rtl_alt = self.params["RTL_RETURN_ALT"] if self.px4 else self.params["RTL_ALT"] / 100.0
        if self.phase == "climb":
            alt = max(rtl_alt, rel[2])
            if rel[2] >= alt - 0.2:
                self.phase = "return"
                self._goto_enu(np.array([self.home_enu[0], self.home_enu[1], self.home_enu[2] + rel[2]]))
            else:
                self._goto_enu(np.array([s.position[0], s.position[1], self.home_enu[2] + alt]))
        elif self.phase == "return":
            if math.hypot(*(s.position[:2] - self.home_enu[:2])) < 0.5 and float(np.linalg.norm(s.velocity)) < 0.3:
                self.phase = "land"
                self._start_land()

    def _cruise_speed(self) -> float:
        """Horizontal speed (m/s) of a position target: ArduCopter flies GUIDED/AUTO/RTL legs at WPNAV_SPEED (cm/s)
        unless MAV_CMD_DO_CHANGE_SPEED set another (AC_WPNav::set_speed_NE_cms); PX4 at MPC_XY_CRUISE, or a
        mission's DO_CHANGE_SPEED, never above MPC_XY_VEL_MAX (OFFBOARD position setpoints without a velocity
        fly at MPC_XY_CRUISE too, as observed; DO_CHANGE_SPEED is a navigator command)."""
        err = self.estimate_speed_error_mps  # the autopilot flies its estimate; the truth is this much faster
        if self.px4:
            base = self.params["MPC_XY_CRUISE"] if self.speed is None or self.mode == "OFFBOARD" else self.speed
            return max(0.1, min(base, self.params["MPC_XY_VEL_MAX"])) + err
        return max(0.1, self.speed if self.speed else self.params["WPNAV_SPEED"] / 100.0) + err

    def _apply_speed_params(self) -> None:
        """The vehicle envelope from the speed parameters (read every control cycle by the firmware, so a
        PARAM_SET changes the leg being flown): horizontal limit, climb rate, acceleration."""
        lim, p = self.veh.limits, self.params
        if self.px4:
            lim.max_speed = max(0.1, p["MPC_XY_VEL_MAX"]) + self.estimate_speed_error_mps
            lim.max_vertical_speed = max(0.1, p["MPC_Z_VEL_MAX_UP"])
            lim.max_acceleration = max(0.1, p["MPC_ACC_HOR"])
        else:  # GUIDED velocity targets too are bounded by the WPNAV speeds (ModeGuided sets the position
            # controller's limits from AC_WPNav's defaults); DO_CHANGE_SPEED may raise them
            lim.max_speed = min(AIRFRAME_MAX_SPEED, max(p["WPNAV_SPEED"] / 100.0, self.speed or 0.0, 0.1)) + \
                self.estimate_speed_error_mps
            lim.max_vertical_speed = max(0.1, p["WPNAV_SPEED_UP"] / 100.0)
            lim.max_acceleration = max(0.1, p["WPNAV_ACCEL"] / 100.0)
        sp = self.veh.setpoint
        if sp.mode == "position":
            sp.speed = self._cruise_speed()

    def _goto_enu(self, target: np.ndarray) -> None:
        sp = self.veh.setpoint
        t = tuple(float(v) for v in target)
        speed = self._cruise_speed()
        if sp.mode == "position" and sp.target == t and sp.speed == speed:
            return
        self.veh.goto(t, speed)
