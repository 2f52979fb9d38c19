"""Actions: readiness as the autopilot itself reports it, arming (with "not yet" refusals retried inside
``arm_timeout_s``), disarming and take-off.

Readiness (both autopilots): a 3-D GPS fix (GPS_RAW_INT ``fix_type`` >= 3) when a GPS reports, HOME_POSITION
received, and the autopilot's own estimator and pre-arm reports:

* ArduPilot: EKF_STATUS_REPORT ``flags`` with attitude, horizontal velocity and an absolute horizontal position
  (``EKF_POS_HORIZ_ABS`` or, disarmed, ``EKF_PRED_POS_HORIZ_ABS``) and not ``EKF_CONST_POS_MODE`` -- the test
  ArduCopter's ``Copter::ekf_has_absolute_position()`` (ArduCopter/system.cpp) applies before arming in a mode
  that needs a position ("Arm: Need Position Estimate"); before any EKF_STATUS_REPORT arrives, the STATUSTEXT
  "EKF3 IMU0 is using GPS" (AP_NavEKF3_Control.cpp) counts as the same. The SYS_STATUS pre-arm bit alone is not
  enough: it reflects the checks of the *current* mode (STABILIZE at boot).
* PX4: SYS_STATUS ``MAV_SYS_STATUS_PREARM_CHECK`` in ``onboard_control_sensors_health`` (PX4 reports it only
  there: ``src/modules/mavlink/streams/SYS_STATUS.hpp`` from the commander's health report), the
  XY_POSITION_CONTROL health bit once the vehicle reports it, HEARTBEAT ``system_status`` MAV_STATE_STANDBY, and
  ESTIMATOR_STATUS (when streamed) with attitude, horizontal velocity and absolute horizontal position.

Even when all of these read ready, an arm can still be refused for a moment (PX4 "Arming denied: Resolve system
health failures first", ArduPilot "PreArm: ..."): MAV_RESULT_FAILED / TEMPORARILY_REJECTED are "not yet" and
retried with back-off (0.5 s doubling to 4 s, wall) until ``arm_timeout_s`` expires; then the last refusal is
raised with the autopilot's text.

A concern object of :class:`~aerodaas.backends.mavlink.MavlinkBackend` (:class:`VehicleAction`), its command group
``actions`` (:class:`~aerodaas.backends.base.Actions`).
"""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Callable, Protocol

from aerodaas.backends.base import CommandRefused
from aerodaas.backends.mavlink._common import M, _PX4_NO_ARM_MODES
from aerodaas.backends.mavlink.command import CommandProtocol
from aerodaas.backends.mavlink.clock import VehicleClock
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink.offboard import OffboardControl
from aerodaas.backends.mavlink.signing import SignedOnly
from aerodaas.backends.mavlink.statustext import StatusTexts
from aerodaas.backends.mavlink.telemetry import Readiness

#: EKF_STATUS_REPORT / ESTIMATOR_STATUS flags (EKF_STATUS_FLAGS, ESTIMATOR_STATUS_FLAGS share these low bits)
_EKF_ATTITUDE, _EKF_VEL_HORIZ, _EKF_POS_HORIZ_ABS = 1, 2, 16
_EKF_CONST_POS_MODE, _EKF_PRED_POS_HORIZ_ABS = 128, 512
#: arm results that mean "not yet" while the vehicle is still getting ready (MAV_RESULT)
_NOT_YET = ("MAV_RESULT_FAILED", "MAV_RESULT_TEMPORARILY_REJECTED")
_ARM_BACKOFF_S = (0.5, 4.0)


class FlightTelemetry(Protocol):
    """What the actions use of the telemetry store (telemetry.py
    :class:`~aerodaas.backends.mavlink.telemetry.VehicleTelemetry`): the altitude reference (AMSL metres, None
    before it is fixed), the flag telling it an :meth:`VehicleAction.arm` runs, fixing the altitude reference where
    the vehicle stands, making a home the autopilot moved after the last flight the ENU origin, and a
    :class:`Readiness` of the latest reports with the link's (caller holds the backend's lock for the last two)."""

    arming: bool

    @property
    def altitude_reference(self) -> float | None: ...

    def fix_altitude_reference(self) -> None: ...

    def home_for_flight(self) -> None: ...

    def readiness(self, system_status: int, ekf_using_gps: bool, ekf_report_unavailable: bool) -> Readiness: ...


class VehicleAction:
    """Readiness, arming, disarming and take-off of one vehicle (see the module docstring).

    It is given its collaborators: ``link`` (the autopilot, its mode and armed flag, the link check, the HEARTBEAT's
    ``system_status``), ``clock`` (vehicle seconds), ``texts`` (ArduPilot's "using GPS" seen), ``commands`` (the
    command protocol), ``telemetry`` (:class:`FlightTelemetry`), ``offboard`` (the guided control: its target
    stream stops before disarming and take-off, and arming puts the vehicle in our control,
    :attr:`OffboardControl.in_control`), ``signed`` (:class:`SignedOnly`: ``mavlink.require_signing`` for arming
    and take-off), ``event`` (records a backend event) and ``lock`` (the backend's lock).
    ``settings``: ``arm_timeout_s``.

    State: whether a mission upload pinned the altitude reference for the next arming."""

    def __init__(self, robot_id: str, settings: Any, *, link: MavlinkLink, clock: VehicleClock, texts: StatusTexts,
                 commands: CommandProtocol, telemetry: FlightTelemetry, offboard: OffboardControl,
                 signed: SignedOnly, event: Callable[..., None], lock: threading.RLock) -> None:
        self.robot_id, self._settings, self._signed = robot_id, settings, signed
        self._link, self._clock, self._texts, self._commands = link, clock, texts, commands
        self._telemetry, self._offboard, self._event, self._lock = telemetry, offboard, event, lock
        self._alt_ref_pinned = False  # fixed by a mission upload on the ground: the next arm() keeps it

    def _readiness(self) -> Readiness:
        """The reports readiness is judged from (telemetry's with the link's). Caller holds ``_lock``."""
        return self._telemetry.readiness(self._link.system_status, self._texts.ekf_using_gps,
                                         self._link.ekf_report_unavailable)

    def pin_altitude_reference(self) -> None:
        """Fix the altitude reference where the vehicle stands now and keep it for the next :meth:`arm` (an uploaded
        mission's altitudes refer to it: mission.py)."""
        self._telemetry.fix_altitude_reference()
        self._alt_ref_pinned = True

    def not_ready_reasons(self) -> list[str]:
        """What the autopilot's own reports say is still missing before it can arm in a guided mode (see the module
        docstring); empty when ready. Never blocks."""
        out: list[str] = []
        with self._lock:
            r = self._readiness()
        if 0 <= r.gps_fix < M.GPS_FIX_TYPE_3D_FIX:
            out.append(f"GPS fix type {r.gps_fix} < 3")
        if not r.home_received and r.gps_fix >= 0:
            out.append("no HOME_POSITION yet")
        present, health, ekf = r.sensors_present, r.sensors_health, r.ekf_flags
        if self._link.autopilot == "px4":
            if not health & M.MAV_SYS_STATUS_PREARM_CHECK:
                out.append("SYS_STATUS pre-arm check not healthy")
            xy = M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
            if (present | r.health_seen) & xy and not health & xy:
                out.append("SYS_STATUS XY position control not healthy")
            if not r.armed and r.system_status != M.MAV_STATE_STANDBY:
                out.append(f"HEARTBEAT system_status {r.system_status} (not STANDBY)")
            if ekf is not None and (ekf & (_EKF_ATTITUDE | _EKF_VEL_HORIZ | _EKF_POS_HORIZ_ABS)
                                    != (_EKF_ATTITUDE | _EKF_VEL_HORIZ | _EKF_POS_HORIZ_ABS)):
                out.append(f"ESTIMATOR_STATUS flags {ekf:#x}: no absolute position")
        else:
            for bit, name in ((M.MAV_SYS_STATUS_PREARM_CHECK, "pre-arm"), (M.MAV_SYS_STATUS_AHRS, "AHRS")):
                if present & bit and not health & bit:
                    out.append(f"SYS_STATUS {name} not healthy")
            if ekf is not None:
                pos = ekf & (_EKF_POS_HORIZ_ABS | _EKF_PRED_POS_HORIZ_ABS)
                if not (ekf & _EKF_ATTITUDE and ekf & _EKF_VEL_HORIZ and pos) or ekf & _EKF_CONST_POS_MODE:
                    out.append(f"EKF_STATUS_REPORT flags {ekf:#x}: no absolute position estimate")
            elif not r.ekf_using_gps and r.gps_fix >= 0 and not r.ekf_report_unavailable:
                out.append("EKF not yet using GPS (no EKF_STATUS_REPORT yet)")
        return out

    def _armable(self) -> bool:
        return not self.not_ready_reasons()

    def arm(self) -> None:
        """Arm for a guided flight, bounded by ``arm_timeout_s`` wall seconds: wait until the autopilot reports
        itself ready (:meth:`not_ready_reasons`), switch to a mode that can arm and take off (ArduPilot GUIDED,
        PX4 LOITER/Hold), send MAV_CMD_COMPONENT_ARM_DISARM, and wait for a HEARTBEAT with the armed flag
        (MAV_MODE_FLAG_SAFETY_ARMED). A refusal with MAV_RESULT_FAILED / TEMPORARILY_REJECTED (a pre-arm check
        still failing) is retried with back-off inside the window; a ``arm_refused`` event records each. An
        ``armed_after`` event gives the wait (wall and vehicle seconds).

        Raises :class:`CommandRefused` (the last refusal: MAV_RESULT name and the autopilot's STATUSTEXT, e.g.
        ``Arm: Need Position Estimate``) when the window expires or for a final result (DENIED, UNSUPPORTED);
        LinkLost / BackendError as :meth:`command_long`; :class:`CommandNotConfirmed` when the vehicle
        acknowledged but never reported itself armed; CredentialsRefused on an unsigned link when
        ``mavlink.require_signing`` (:class:`SignedOnly`)."""
        self._signed.require("arm")
        self._link.check_link("arm")
        with self._lock:  # a new flight: its home (where it arms) becomes the ENU origin (telemetry.py)
            self._telemetry.arming = True
            self._telemetry.home_for_flight()
        try:
            self._arm()
        finally:
            self._telemetry.arming = False

    def _arm(self) -> None:
        start, t0 = time.monotonic(), self._clock.t
        end = start + self._settings.arm_timeout_s
        while self.not_ready_reasons() and time.monotonic() < end:
            self._link.check_link("arm")
            time.sleep(0.02)
        backoff, tries = _ARM_BACKOFF_S[0], 0
        while True:
            tries += 1
            try:
                # not ready when the window closed: ask in the current mode, so the refusal carries the
                # autopilot's pre-arm reason (a guided mode would be refused first, without it)
                autopilot, mode = self._link.autopilot, self._link.mode
                if autopilot == "ardupilot" and mode != "GUIDED" and self._armable():
                    self._commands.set_mode("GUIDED")
                elif autopilot == "px4" and mode in _PX4_NO_ARM_MODES and self._armable():
                    self._commands.set_mode("LOITER")
                sent = time.monotonic()
                armed = lambda: self._link.armed  # noqa: E731 - what the HEARTBEAT must show
                self._commands.command_with_effect("arm", armed, M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
                self._commands.await_heartbeat("arm", armed, "armed", None, sent)
                break
            except CommandRefused as e:
                if e.result not in _NOT_YET or time.monotonic() + backoff > end:
                    raise
                self._event("arm_refused", result=e.result, text=e.status_text, command=e.command,
                            not_ready=self.not_ready_reasons())
                stop = time.monotonic() + backoff
                while time.monotonic() < stop:
                    self._link.check_link("arm")
                    time.sleep(0.02)
                backoff = min(backoff * 2.0, _ARM_BACKOFF_S[1])
        if not self._alt_ref_pinned:  # an uploaded mission's altitudes refer to the one fixed at upload
            self._telemetry.fix_altitude_reference()
        self._alt_ref_pinned = False
        self._offboard.take_control()
        self._event("armed_after", wall_s=round(time.monotonic() - start, 3),
                    vehicle_s=round(self._clock.t - t0, 3), tries=tries)

    def disarm(self) -> None:
        """MAV_CMD_COMPONENT_ARM_DISARM(0); autopilots refuse it in flight (CommandRefused)."""
        self._offboard.stop()
        self._commands.command_long("disarm", M.MAV_CMD_COMPONENT_ARM_DISARM, 0)

    def takeoff(self, altitude_m: float) -> None:
        """MAV_CMD_NAV_TAKEOFF to ``altitude_m`` metres above the take-off point. The altitude reference (the
        take-off point's AMSL altitude from GLOBAL_POSITION_INT, fixed when arming) is used on both autopilots
        (ArduPilot: in GUIDED, ``param7`` relative to home, which ArduPilot sets at arming = the take-off point;
        PX4: ``param7`` AMSL = reference + ``altitude_m``, position NaN = here; PX4 holds (LOITER) when there).
        Raises CredentialsRefused on an unsigned link when ``mavlink.require_signing``; ValueError for a
        non-positive or non-finite altitude; CommandRefused / LinkLost / BackendError."""
        self._signed.require("takeoff")
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"takeoff altitude_m must be a positive number of metres, got {altitude_m!r}")
        self._link.check_link("takeoff")
        self._offboard.stop()
        if self._telemetry.altitude_reference is None:
            self._telemetry.fix_altitude_reference()
        if self._link.autopilot == "px4":
            nan = float("nan")
            self._commands.command_long("takeoff", M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan,
                                        self._telemetry.altitude_reference + altitude_m)
        else:
            if self._link.mode != "GUIDED":
                self._commands.set_mode("GUIDED")
            self._commands.command_long("takeoff", M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, altitude_m)
