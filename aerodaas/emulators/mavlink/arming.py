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

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.model.geo import enu_to_geodetic
from aerodaas.emulators.mavlink.constants import _AP_ARMABLE, _AP_NEEDS_POSITION, _PX4_MANUAL
from aerodaas.emulators.mavlink.flavour import (AP_PREARM_DISPLAY_PERIOD_S, AP_SENSORS, EKF_NO_POSITION, EKF_POSITION,
                      PX4_HOME_CORRECTION_STEP_M, PX4_HOME_CORRECTION_WINDOW_S, PX4_SENSORS)

M = mavlink


class ArmingMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator` (state lives there)."""

    def set_prearm_failure(self, text: str | None) -> None:
        """Make pre-arm checks fail with ``text`` (e.g. ``"Compass not calibrated"``); None clears it."""
        with self._lock:
            self.prearm_failure = text

    # ------------------------------------------------------------------ estimator
    def _position_ok(self) -> bool:
        """The EKF has a horizontal position estimate (vehicle seconds ``gps_lock_s + ekf_gps_s``)."""
        return self.home is not None and self.t >= self.gps_lock_s + self.ekf_gps_s

    def _readiness_tick(self) -> None:
        """Per physics step: announce the position estimate, repeat ArduPilot's failing pre-arm checks every 30 s
        while disarmed, correct PX4's home altitude after take-off."""
        if not self._position_ok_sent and self._position_ok():
            self._position_ok_sent = True
            if not self.px4:
                self._text(M.MAV_SEVERITY_INFO, "EKF3 IMU0 is using GPS")
        if not self.px4 and self.t >= self._next_prearm_report:
            self._next_prearm_report = self.t + AP_PREARM_DISPLAY_PERIOD_S
            why = None if self.veh.state.armed else self._prearm()
            if why:
                self._text(M.MAV_SEVERITY_CRITICAL, f"PreArm: {why}")
        if self.px4 and self.home_alt_drift_m > 0 and self.took_off_at is not None \
                and self.params.get("COM_HOME_EN", 1.0) >= 0.5:
            self._home_alt_correction()

    def _home_alt_correction(self) -> None:
        """PX4 HomePosition::update: within 120 s of take-off, when the baro/GPS altitude disagreement moved more
        than 1 m since the last correction, home.alt moves by it (emulated as a bounded random walk, 1 Hz)."""
        err, applied, due = self._home_corr
        if self.t - self.took_off_at > PX4_HOME_CORRECTION_WINDOW_S or self.t < due or self.home is None:
            return
        bound = self.home_alt_drift_m
        err = float(np.clip(err + self._rng.normal(0.0, 0.6 * bound), -bound, bound))
        if abs(err - applied) > PX4_HOME_CORRECTION_STEP_M:
            self.home_enu = self.home_enu + np.array([0.0, 0.0, err - applied])
            h = self.home_enu
            self.home = enu_to_geodetic(float(h[0]), float(h[1]), float(h[2]), self.origin)
            applied = err
            self._emit(M.MAVLINK_MSG_ID_HOME_POSITION)
        self._home_corr = (err, applied, self.t + 1.0)

    def _ekf_flags(self) -> int:
        """ArduPilot EKF_STATUS_REPORT.flags for the estimator's state."""
        return EKF_POSITION if self._position_ok() else EKF_NO_POSITION

    def _sensors(self) -> tuple[int, int, int]:
        """SYS_STATUS (present, enabled, health) bit masks (MAV_SYS_STATUS_SENSOR)."""
        present = PX4_SENSORS if self.px4 else AP_SENSORS
        health = present
        if self._fix_type() < 3:
            health &= ~M.MAV_SYS_STATUS_SENSOR_GPS
        if not self._position_ok():
            health &= ~M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
        if self.px4:
            if self._prearm() is None:  # PX4 sets the pre-arm bit in health only
                health |= M.MAV_SYS_STATUS_PREARM_CHECK
            return present, present, health
        if self.home is None:
            health &= ~M.MAV_SYS_STATUS_AHRS
        if self._prearm() is not None:
            health &= ~M.MAV_SYS_STATUS_PREARM_CHECK
        return present, present, health

    # ------------------------------------------------------------------ pre-arm checks and arming
    def _prearm(self, mode: str | None = None) -> str | None:
        """The first failing pre-arm check for ``mode`` (default: the current one), in the autopilot's words
        without its prefix, or None."""
        mode = mode or self.mode
        if self.prearm_failure:
            return self.prearm_failure
        if self.px4:
            if self._fix_type() < 3:
                return "GPS fix too low"
            if not self._position_ok():
                return "heading estimate not stable"  # as seen on PX4 SIH before the EKF has converged
            return None
        if mode not in _AP_NEEDS_POSITION:
            return None
        if self.home is None:
            return "AHRS: waiting for home"
        if not self._position_ok():
            return "Need Position Estimate"
        return None

    def _arm(self, force: bool) -> int:
        s = self.veh.state
        if s.armed:
            return M.MAV_RESULT_ACCEPTED
        if not force:
            if self.px4:
                why = self._prearm()  # health checks first (PX4 reports every failing check; we send the first)
                if why:
                    self._text(M.MAV_SEVERITY_CRITICAL, f"Preflight Fail: {why}")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
                if self.mode in _PX4_MANUAL:
                    self._text(M.MAV_SEVERITY_CRITICAL, "Preflight Fail: No manual control input")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
                if self.mode in ("AUTO.RTL", "AUTO.LAND"):
                    self._text(M.MAV_SEVERITY_CRITICAL, f"Arming denied: {self.mode} mode not armable")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
                if self.mode == "OFFBOARD" and not self._offboard_stream_ok():
                    self._text(M.MAV_SEVERITY_CRITICAL, "Preflight Fail: offboard control signal lost")
                    return M.MAV_RESULT_TEMPORARILY_REJECTED
            else:
                if self.mode not in _AP_ARMABLE:
                    self._text(M.MAV_SEVERITY_CRITICAL, "Arm: Mode not armable")
                    return M.MAV_RESULT_FAILED
                why = self._prearm()
                if why:
                    self._text(M.MAV_SEVERITY_CRITICAL, f"Arm: {why}")
                    return M.MAV_RESULT_FAILED
        self.veh.arm()
        self.armed_at = self.t
        self.took_off = False
        self.took_off_at = None
        self._home_corr = (0.0, 0.0, 0.0)
        self.landed_at = None
        if self._fix_type() >= 3:
            self._set_home_here()  # both autopilots reset home to where they arm
        self._text(M.MAV_SEVERITY_INFO, "Arming motors" if not self.px4 else "Armed by external command")
        return M.MAV_RESULT_ACCEPTED
