"""How the emulated autopilot moves the flight model: position legs at the firmware's cruise speed, take-off and
landing, position/velocity targets (ArduPilot GUIDED, PX4 OFFBOARD) and the speed envelope from the speed
parameters."""
from __future__ import annotations

import numpy as np

from aerodaas.emulators.mavlink.flavour import AIRFRAME_MAX_SPEED
from aerodaas.emulators.mavlink.state import EmulatorState

__all__ = ["Motion"]


class Motion:
    """The position controller of the emulated firmware over ``state`` (its flight model, mode, parameters and
    targets). Not locked: the vehicle calls it under its lock."""

    def __init__(self, state: EmulatorState) -> None:
        self.state = state

    def cruise_speed(self) -> float:
        """Horizontal speed (m/s) of a position target: ArduCopter flies GUIDED/AUTO/RTL legs at WPNAV_SPEED (cm/s)
        unless MAV_CMD_DO_CHANGE_SPEED set another (AC_WPNav::set_speed_NE_cms); PX4 at MPC_XY_CRUISE, or a
        mission's DO_CHANGE_SPEED, never above MPC_XY_VEL_MAX (OFFBOARD position setpoints without a velocity
        fly at MPC_XY_CRUISE too, as observed; DO_CHANGE_SPEED is a navigator command)."""
        st = self.state
        err = st.estimate_speed_error_mps  # the autopilot flies its estimate; the truth is this much faster
        if st.px4:
            base = st.params["MPC_XY_CRUISE"] if st.speed is None or st.mode == "OFFBOARD" else st.speed
            return max(0.1, min(base, st.params["MPC_XY_VEL_MAX"])) + err
        return max(0.1, st.speed if st.speed else st.params["WPNAV_SPEED"] / 100.0) + err

    def land_speed(self) -> float:
        """Descent speed (m/s) when landing: PX4 MPC_LAND_SPEED (m/s), ArduCopter LAND_SPEED (cm/s)."""
        p = self.state.params
        return p["MPC_LAND_SPEED"] if self.state.px4 else p["LAND_SPEED"] / 100.0

    def land_speed_high(self) -> float:
        """Descent speed (m/s) when landing from above 10 m: PX4 MPC_Z_VEL_MAX_DN (m/s; its auto descent
        MPC_Z_V_AUTO_DN has the same 1.5 m/s default), ArduCopter WPNAV_SPEED_DN (cm/s, LAND_SPEED_HIGH 0)."""
        p = self.state.params
        return p["MPC_Z_VEL_MAX_DN"] if self.state.px4 else p["WPNAV_SPEED_DN"] / 100.0

    def apply_speed_params(self) -> None:
        """The vehicle envelope from the speed parameters (read every control cycle by the firmware, so a
        PARAM_SET changes the leg being flown): horizontal limit, climb rate, acceleration."""
        st = self.state
        lim, p = st.veh.limits, st.params
        if st.px4:
            lim.max_speed = max(0.1, p["MPC_XY_VEL_MAX"]) + st.estimate_speed_error_mps
            lim.max_vertical_speed = max(0.1, p["MPC_Z_VEL_MAX_UP"])
            lim.max_acceleration = max(0.1, p["MPC_ACC_HOR"])
        else:  # GUIDED velocity targets too are bounded by the WPNAV speeds (ModeGuided sets the position
            # controller's limits from AC_WPNav's defaults); DO_CHANGE_SPEED may raise them
            lim.max_speed = min(AIRFRAME_MAX_SPEED, max(p["WPNAV_SPEED"] / 100.0, st.speed or 0.0, 0.1)) + \
                st.estimate_speed_error_mps
            lim.max_vertical_speed = max(0.1, p["WPNAV_SPEED_UP"] / 100.0)
            lim.max_acceleration = max(0.1, p["WPNAV_ACCEL"] / 100.0)
        sp = st.veh.setpoint
        if sp.mode == "position":
            sp.speed = self.cruise_speed()

    def goto_enu(self, target: np.ndarray) -> None:
        """Fly to ``target`` (ENU metres from the EKF origin, shape (3,)) at the cruise speed (unchanged when it
        is already the leg being flown)."""
        veh = self.state.veh
        sp = veh.setpoint
        t = tuple(float(v) for v in target)
        speed = self.cruise_speed()
        if sp.mode == "position" and sp.target == t and sp.speed == speed:
            return
        veh.goto(t, speed)

    def start_takeoff(self, rel_alt: float) -> None:
        """Climb straight up to ``rel_alt`` metres above home."""
        st = self.state
        s = st.veh.state
        st.takeoff_alt = float(rel_alt)
        self.goto_enu(np.array([s.position[0], s.position[1], st.home_enu[2] + st.takeoff_alt]))

    def start_land(self) -> None:
        """Descend where the vehicle is: at :meth:`land_speed_high` above 10 m, then at :meth:`land_speed` (m/s)."""
        veh = self.state.veh
        veh.land()
        veh.setpoint.land_speed, veh.setpoint.land_speed_high = self.land_speed(), self.land_speed_high()
        self.state.takeoff_alt = None

    def track_posvel(self) -> None:
        """Position + velocity target: the autopilots' position loop, v = v_ff + Kp (p_sp - p) (PX4 MPC_XY_P
        0.95, ArduPilot PSC_POSXY_P 1.0), re-evaluated every physics step."""
        st = self.state
        pos, vel = st.posvel
        kp = 0.95 if st.px4 else 1.0
        v = vel + kp * (pos - st.veh.state.position)
        st.veh.set_velocity(tuple(float(c) for c in v), 0.0)

    def fly_target(self, pos_enu: np.ndarray | None, vel_enu: np.ndarray | None, yaw_rate_dps: float | None) -> None:
        """Act on a position (ENU m) and/or velocity (ENU m/s) target when the firmware would: ArduPilot in GUIDED
        once it has taken off (or is taking off), PX4 in OFFBOARD; armed. A velocity alone times out after 3 s on
        ArduPilot."""
        st = self.state
        s = st.veh.state
        if st.px4 and st.mode != "OFFBOARD":
            return  # PX4 records every setpoint; it acts on them in OFFBOARD only
        if not st.px4 and st.mode != "GUIDED":
            return
        if not s.armed:
            return
        if not st.px4 and not s.in_air and st.takeoff_alt is None:
            return  # ArduPilot ignores guided targets until it has taken off
        st.posvel = None
        if pos_enu is not None and vel_enu is not None:  # position with velocity feed-forward
            st.velocity_deadline = None
            st.takeoff_alt = None
            st.posvel = (np.asarray(pos_enu, float), np.asarray(vel_enu, float))
            self.track_posvel()
        elif pos_enu is not None:
            st.velocity_deadline = None
            st.takeoff_alt = None
            self.goto_enu(pos_enu)
        elif vel_enu is not None:
            st.takeoff_alt = None
            st.veh.set_velocity(tuple(float(v) for v in vel_enu), float(yaw_rate_dps or 0.0))
            if not st.px4:
                st.velocity_deadline = st.t + 3.0
