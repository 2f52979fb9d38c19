"""Actions: readiness, arming, disarming and take-off."""
from __future__ import annotations

import math
import time


from ._common import M, _PX4_NO_ARM_MODES


class ActionMixin:
    """Part of :class:`~aerodaas.backends.mavlink.MavlinkBackend` (see its docstring for the shared state)."""

    # ------------------------------------------------------------------ VehicleBackend: control
    def _armable(self) -> bool:
        with self._lock:
            if self._gps_fix >= 0 and self._gps_fix < M.GPS_FIX_TYPE_3D_FIX:
                return False
            if self._sensors is not None:
                present, _, health = self._sensors
                for bit in (M.MAV_SYS_STATUS_PREARM_CHECK, M.MAV_SYS_STATUS_AHRS):
                    if present & bit and not health & bit:
                        return False
            return True

    def arm(self) -> None:
        """Wait up to ``arm_timeout_s`` until the autopilot reports itself armable (3-D fix in GPS_RAW_INT,
        SYS_STATUS pre-arm and AHRS health bits when present), switch to a mode that can arm and take off
        (ArduPilot GUIDED, PX4 LOITER/Hold), then MAV_CMD_COMPONENT_ARM_DISARM. If it never becomes armable the
        arm command is sent anyway in the current mode, so the :class:`CommandRefused` carries the autopilot's
        reason (e.g. ``PreArm: ...``). Once acknowledged, waits (like :meth:`set_mode`) for a HEARTBEAT with the
        armed flag (MAV_MODE_FLAG_SAFETY_ARMED). Raises CommandRefused / LinkLost / BackendError as
        :meth:`command_long`, :class:`CommandNotConfirmed` when the vehicle acknowledged but never reported
        itself armed."""
        self._check_link("arm")
        end = time.monotonic() + self.cfg.arm_timeout_s
        while not self._armable() and time.monotonic() < end:
            self._check_link("arm")
            time.sleep(0.02)
        if self._armable():
            if self.autopilot == "ardupilot" and self._mode != "GUIDED":
                self.set_mode("GUIDED")
            elif self.autopilot == "px4" and self._mode in _PX4_NO_ARM_MODES:
                self.set_mode("LOITER")
        sent = time.monotonic()
        self.command_long("arm", M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        self._await_heartbeat("arm", lambda: self._armed, "armed", None, sent)

    def disarm(self) -> None:
        """MAV_CMD_COMPONENT_ARM_DISARM(0); autopilots refuse it in flight (CommandRefused)."""
        self._stop_setpoints()
        self.command_long("disarm", M.MAV_CMD_COMPONENT_ARM_DISARM, 0)

    def takeoff(self, altitude_m: float) -> None:
        """MAV_CMD_NAV_TAKEOFF to ``altitude_m`` metres above home. ArduPilot: in GUIDED, ``param7`` relative;
        PX4: ``param7`` AMSL (home altitude from GLOBAL_POSITION_INT alt - relative_alt), position NaN = here;
        PX4 holds (LOITER) when it gets there. Raises ValueError for a non-positive or non-finite altitude."""
        self._require_navigable("takeoff")
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"takeoff altitude_m must be a positive number of metres, got {altitude_m!r}")
        self._check_link("takeoff")
        self._stop_setpoints()
        if self.autopilot == "px4":
            with self._lock:
                home_amsl = (self._geo.alt - self._rel_alt) if self._geo is not None else self.home.alt
            nan = float("nan")
            self.command_long("takeoff", M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, home_amsl + altitude_m)
        else:
            if self._mode != "GUIDED":
                self.set_mode("GUIDED")
            self.command_long("takeoff", M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, altitude_m)

