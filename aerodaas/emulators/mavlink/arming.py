"""Readiness and arming: pre-arm checks, the arm command."""
from __future__ import annotations


from pymavlink.dialects.v20 import ardupilotmega as mavlink

from .constants import _AP_ARMABLE, _PX4_MANUAL


M = mavlink


class ArmingMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator` (state lives there)."""

    def set_prearm_failure(self, text: str | None) -> None:
        """Make pre-arm checks fail with ``text`` (e.g. ``"Compass not calibrated"``); None clears it."""
        with self._lock:
            self.prearm_failure = text

    def _prearm(self) -> str | None:
        """The first failing pre-arm check, in the autopilot's words, or None."""
        if self.prearm_failure:
            return self.prearm_failure
        if self._fix_type() < 3:
            return "Need 3D Fix" if not self.px4 else "GPS fix too low"
        if self.home is None:
            return "Need Position Estimate" if not self.px4 else "Home position invalid"
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
                    self._text(M.MAV_SEVERITY_CRITICAL, f"PreArm: {why}")
                    return M.MAV_RESULT_FAILED
        self.veh.arm()
        self.armed_at = self.t
        self.took_off = False
        self.landed_at = None
        if self._fix_type() >= 3:
            self._set_home_here()  # both autopilots reset home to where they arm
        self._text(M.MAV_SEVERITY_INFO, "Arming motors" if not self.px4 else "Armed by external command")
        return M.MAV_RESULT_ACCEPTED
