"""Readiness and arming as the firmware defines them: the estimator's progress (GPS fix -> EKF origin/home ->
position estimate), the health it reports (SYS_STATUS, ArduPilot EKF_STATUS_REPORT), pre-arm checks per flight
mode, the arm command, and PX4's in-flight home-altitude correction.

Firmware behaviour reproduced (observed with :mod:`.trace` on ArduCopter and PX4 SITL):

* ArduCopter: the GPS fix gives "EKF3 IMU0 origin set" and home; seconds later "EKF3 IMU0 is using GPS" gives the
  position estimate. Arming in a mode that needs a position (GUIDED, LOITER, AUTO ...) is refused
  MAV_RESULT_FAILED with "Arm: AHRS: waiting for home" before the origin and "Arm: Need Position Estimate" until
  the EKF uses GPS (ArduCopter/AP_Arming_Copter.cpp mandatory_gps_checks); the same checks are repeated as
  "PreArm: ..." every 30 s while disarmed (libraries/AP_Arming/AP_Arming.cpp). The SYS_STATUS PREARM_CHECK health
  bit reflects the checks of the *current* mode (STABILIZE needs no position).
* PX4: arming is refused MAV_RESULT_TEMPORARILY_REJECTED with "Preflight Fail: ..." until the health checks pass
  (src/modules/commander/HealthAndArmingChecks); the position estimate shows as the XY_POSITION_CONTROL health
  bit; AHRS and PREARM_CHECK are not reported as present (src/modules/mavlink/streams/SYS_STATUS.hpp). For
  120 s after take-off the home altitude is corrected in steps over 1 m (src/modules/commander/HomePosition.cpp,
  COM_HOME_EN): here a seeded random walk bounded by ``home_alt_drift_m``.
"""
from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.model.geo import enu_to_geodetic
from aerodaas.emulators.mavlink.constants import _AP_ARMABLE, _PX4_MANUAL
from aerodaas.emulators.mavlink.flavour import (AP_PREARM_DISPLAY_PERIOD_S, PX4_HOME_CORRECTION_STEP_M,
                                               PX4_HOME_CORRECTION_WINDOW_S, PX4_HOME_MOVED_M)
from aerodaas.emulators.mavlink.link import EmulatorLink
from aerodaas.emulators.mavlink.state import EmulatorState
from aerodaas.emulators.mavlink.telemetry import Telemetry

M = mavlink

__all__ = ["Arming"]


class Arming:
    """Readiness, home and arming of the emulated firmware: the estimator's announcements and ArduPilot's repeated
    pre-arm report (:meth:`readiness_tick`), home (:meth:`set_home_here`, PX4's in-flight altitude correction from a
    random walk seeded with ``seed``), the arm command and disarming, over ``state`` (the checks themselves:
    :meth:`.state.EmulatorState.prearm`), telling the ground stations on ``link`` and announcing home with
    ``telemetry``. Not locked: the vehicle calls it under its lock."""

    def __init__(self, state: EmulatorState, link: EmulatorLink, telemetry: Telemetry, seed: int = 0) -> None:
        self.state, self.link, self.telemetry = state, link, telemetry
        self._rng = np.random.default_rng(seed)
        self._position_ok_sent = False
        self._next_prearm_report = AP_PREARM_DISPLAY_PERIOD_S
        self._home_corr = (0.0, 0.0, 0.0)  # PX4 home-altitude correction: (error m, applied m, next update s)

    def set_home_here(self) -> None:
        """Home is where the vehicle is (:meth:`.state.EmulatorState.set_home_here`), announced as HOME_POSITION."""
        self.state.set_home_here()
        self.telemetry.emit(M.MAVLINK_MSG_ID_HOME_POSITION)

    # ------------------------------------------------------------------ estimator
    def readiness_tick(self) -> None:
        """Per physics step: announce the position estimate, repeat ArduPilot's failing pre-arm checks every 30 s
        while disarmed, correct PX4's home altitude after take-off."""
        st = self.state
        if not self._position_ok_sent and st.position_ok():
            self._position_ok_sent = True
            if not st.px4:
                self.link.text(M.MAV_SEVERITY_INFO, "EKF3 IMU0 is using GPS")
        if not st.px4 and st.t >= self._next_prearm_report:
            self._next_prearm_report = st.t + AP_PREARM_DISPLAY_PERIOD_S
            why = None if st.veh.state.armed else st.prearm()
            if why:
                self.link.text(M.MAV_SEVERITY_CRITICAL, f"PreArm: {why}")
        if st.px4 and st.home_alt_drift_m > 0 and st.took_off_at is not None \
                and st.params.get("COM_HOME_EN", 1.0) >= 0.5:
            self._home_alt_correction()

    def _home_alt_correction(self) -> None:
        """PX4 HomePosition::update: within 120 s of take-off, when the baro/GPS altitude disagreement moved more
        than 1 m since the last correction, home.alt moves by it (emulated as a bounded random walk, 1 Hz)."""
        st = self.state
        err, applied, due = self._home_corr
        if st.t - st.took_off_at > PX4_HOME_CORRECTION_WINDOW_S or st.t < due or st.home is None:
            return
        bound = st.home_alt_drift_m
        err = float(np.clip(err + self._rng.normal(0.0, 0.6 * bound), -bound, bound))
        if abs(err - applied) > PX4_HOME_CORRECTION_STEP_M:
            st.home_enu = st.home_enu + np.array([0.0, 0.0, err - applied])
            h = st.home_enu
            st.home = enu_to_geodetic(float(h[0]), float(h[1]), float(h[2]), st.origin)
            applied = err
            self.telemetry.emit(M.MAVLINK_MSG_ID_HOME_POSITION)
        self._home_corr = (err, applied, st.t + 1.0)

    # ------------------------------------------------------------------ arming and disarming
    def arm_disarm(self, p: list[float]) -> int:
        """MAV_CMD_COMPONENT_ARM_DISARM (param1 >= 0.5 arms, param2 21196 forces): its MAV_RESULT. A disarm in the
        air, or on PX4 before its land detector confirmed the landing, is refused as the firmware refuses it."""
        st = self.state
        s = st.veh.state
        force = int(round(p[1])) == 21196
        if p[0] >= 0.5:
            return self.arm(force)
        if s.armed and not force and st.px4 and not s.in_air and st.landed_at is not None and \
                st.t - st.landed_at < st.land_detect_s:  # PX4's land detector has not said landed yet
            self.link.text(M.MAV_SEVERITY_CRITICAL, "Disarming denied: not landed")
            return M.MAV_RESULT_TEMPORARILY_REJECTED
        if s.armed and s.in_air and not force:
            if st.px4:
                self.link.text(M.MAV_SEVERITY_CRITICAL, "Disarming denied: not landed")
                return M.MAV_RESULT_TEMPORARILY_REJECTED
            self.link.text(M.MAV_SEVERITY_CRITICAL, "Disarm: vehicle is flying")
            return M.MAV_RESULT_FAILED
        if s.armed:
            s.in_air = False
            self.disarm("external command")
        return M.MAV_RESULT_ACCEPTED

    def _refusal(self) -> str | None:
        """Why the firmware refuses to arm now (its STATUSTEXT), or None (PX4 HealthAndArmingChecks, ArduCopter
        AP_Arming_Copter)."""
        st = self.state
        if st.px4:
            why = st.prearm()  # health checks first (PX4 reports every failing check; we send the first)
            if why:
                return f"Preflight Fail: {why}"
            if st.mode in _PX4_MANUAL:
                return "Preflight Fail: No manual control input"
            if st.mode in ("AUTO.RTL", "AUTO.LAND"):
                return f"Arming denied: {st.mode} mode not armable"
            if st.mode == "OFFBOARD" and not st.offboard_stream_ok():
                return "Preflight Fail: offboard control signal lost"
            return None
        if st.mode not in _AP_ARMABLE:
            return "Arm: Mode not armable"
        why = st.prearm()
        return f"Arm: {why}" if why else None

    def arm(self, force: bool) -> int:
        """Arm (``force``: without the checks): its MAV_RESULT (PX4 TEMPORARILY_REJECTED, ArduPilot FAILED, with
        the reason as STATUSTEXT). Home is reset to where the vehicle arms, as both autopilots do."""
        st = self.state
        s = st.veh.state
        if s.armed:
            return M.MAV_RESULT_ACCEPTED
        why = None if force else self._refusal()
        if why:
            self.link.text(M.MAV_SEVERITY_CRITICAL, why)
            return M.MAV_RESULT_TEMPORARILY_REJECTED if st.px4 else M.MAV_RESULT_FAILED
        st.veh.arm()
        st.armed_at = st.t
        st.took_off = False
        st.took_off_at = None
        self._home_corr = (0.0, 0.0, 0.0)
        st.landed_at = None
        if st.fix_type() >= 3:
            self.set_home_here()  # both autopilots reset home to where they arm
        self.link.text(M.MAV_SEVERITY_INFO, "Arming motors" if not st.px4 else "Armed by external command")
        return M.MAV_RESULT_ACCEPTED

    def disarm(self, why: str) -> None:
        """Disarm (``why``: the firmware's reason in its STATUSTEXT); PX4 moves home to a vehicle that landed away
        from it."""
        st = self.state
        s = st.veh.state
        s.armed = False
        s.velocity[:] = 0.0
        st.veh.setpoint.mode = "idle"
        st.takeoff_alt = None
        st.phase = ""
        st.landed_at = None
        self.link.text(M.MAV_SEVERITY_INFO, f"Disarming motors ({why})" if not st.px4 else f"Disarmed by {why}")
        if st.px4 and st.home_enu is not None and st.params.get("COM_HOME_EN", 1.0) >= 0.5 \
                and math.hypot(*(s.position[:2] - st.home_enu[:2])) > PX4_HOME_MOVED_M:
            # PX4 commander, disarmed and landed: home follows the vehicle once it moved from it by more than
            # twice the GPS eph (HomePosition::update, hasMovedFromCurrentHomeLocation; SIH GPS eph 0.9 m)
            self.set_home_here()
