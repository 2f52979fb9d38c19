"""Constants and helpers shared by the MAVLink backend's modules: message/type-mask tables, the telemetry
streams requested, :class:`CommandNotConfirmed`, enum names and float32 rounding."""
from __future__ import annotations

import logging

from aerodaas.backends.base import BackendError
from aerodaas.missionfile.items import float32


#: STATUSTEXT lines are logged here (``robot: text``), at the level of their MAV_SEVERITY
log = logging.getLogger("aerodaas.mavlink")

from pymavlink.dialects.v20 import ardupilotmega as M  # constants and enum names

#: MAV_TYPE values that are not vehicles (ground stations, companions, peripherals)
_NOT_VEHICLES = {M.MAV_TYPE_GCS, M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_TYPE_GIMBAL, M.MAV_TYPE_ADSB,
                 M.MAV_TYPE_CAMERA, M.MAV_TYPE_CHARGING_STATION, M.MAV_TYPE_FLARM, M.MAV_TYPE_SERVO,
                 M.MAV_TYPE_ODID, M.MAV_TYPE_ANTENNA_TRACKER}
_MULTIROTORS = {M.MAV_TYPE_QUADROTOR, M.MAV_TYPE_COAXIAL, M.MAV_TYPE_HEXAROTOR, M.MAV_TYPE_OCTOROTOR,
                M.MAV_TYPE_TRICOPTER, M.MAV_TYPE_DODECAROTOR, M.MAV_TYPE_HELICOPTER, M.MAV_TYPE_DECAROTOR}
#: modes an autopilot enters by itself on a failsafe (ArduCopter FS_* / FENCE_ACTION: RTL, SMART_RTL, LAND, BRAKE,
#: AUTO_RTL; PX4 COM_*_ACT / GF_ACTION / NAV_DLL_ACT: AUTO.RTL, AUTO.LAND, AUTO.LOITER is "Hold" and also an
#: ordinary mode, so not counted). Entered without our asking, they are the autopilot's failsafe (or a pilot's
#: switch): the mission pauses (offboard.py, actors/drone/component.py ``mavlink.on_failsafe``)
FAILSAFE_MODES = {"ardupilot": {"RTL", "SMART_RTL", "LAND", "BRAKE", "AUTO_RTL"}, "px4": {"RTL", "LAND"}}
_AP_ARM_MODES = {"GUIDED", "LOITER", "STABILIZE", "ALT_HOLD", "POSHOLD", "BRAKE"}
_PX4_NO_ARM_MODES = {"MANUAL", "ALTCTL", "POSCTL", "ACRO", "STABILIZED", "RATTITUDE", "RTL", "LAND"}
# POSITION_TARGET_TYPEMASK: bits set = ignored
_IGNORE_POS = 0b111
_IGNORE_VEL = 0b111000
_IGNORE_ACC = 0b111000000
_IGNORE_YAW = 1024
_IGNORE_YAW_RATE = 2048
POSITION_ONLY_MASK = _IGNORE_VEL | _IGNORE_ACC | _IGNORE_YAW | _IGNORE_YAW_RATE
VELOCITY_ONLY_MASK = _IGNORE_POS | _IGNORE_ACC | _IGNORE_YAW  # yaw rate is used
POSITION_VELOCITY_MASK = _IGNORE_ACC | _IGNORE_YAW | _IGNORE_YAW_RATE  # velocity as feed-forward
_GLOBAL_FRAMES = {0, 3, 5, 6, 10, 11}
_TELEMETRY = ((M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, None), (M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, None),
              (M.MAVLINK_MSG_ID_ATTITUDE, None), (M.MAVLINK_MSG_ID_SYS_STATUS, 2.0), (M.MAVLINK_MSG_ID_GPS_RAW_INT, 5.0),
              (M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 2.0), (M.MAVLINK_MSG_ID_BATTERY_STATUS, 1.0),
              (M.MAVLINK_MSG_ID_HOME_POSITION, 0.5), (M.MAVLINK_MSG_ID_MISSION_CURRENT, 1.0),
              (M.MAVLINK_MSG_ID_SYSTEM_TIME, 1.0))
#: per autopilot, the estimator report that says when it has a position (action.py readiness), 2 Hz
_ESTIMATOR_STREAM = {"ardupilot": (M.MAVLINK_MSG_ID_EKF_STATUS_REPORT, 2.0),
                     "px4": (M.MAVLINK_MSG_ID_ESTIMATOR_STATUS, 2.0)}
#: wall seconds without a timestamped message after which the vehicle clock is extrapolated (clock.py)
_CLOCK_STALE_S = 0.5
_LEGACY_STREAMS = ((M.MAV_DATA_STREAM_EXTENDED_STATUS, 2.0), (M.MAV_DATA_STREAM_POSITION, None),
                   (M.MAV_DATA_STREAM_EXTRA1, None), (M.MAV_DATA_STREAM_EXTRA3, 1.0))
#: STATUSTEXT.text is char[50]; a MAVLink 2 chunk shorter than that (NUL-terminated) ends a long text
_STATUSTEXT_LEN = 50
#: wall seconds after its first chunk that a long STATUSTEXT whose last chunk never came is emitted as it is
_STATUSTEXT_FLUSH_S = 0.5
#: wall seconds to wait before re-sending a command answered MAV_RESULT_TEMPORARILY_REJECTED (at most the timeout)
_REJECTED_BACKOFF_S = 0.5


class CommandNotConfirmed(BackendError):
    """The autopilot acknowledged a command (COMMAND_ACK MAV_RESULT_ACCEPTED) but no HEARTBEAT showed its effect
    (the requested mode, or the armed flag) within the bounded wait. ``expected`` is what was asked (e.g.
    ``"mode GUIDED"``, ``"armed"``), ``observed`` what the latest HEARTBEAT shows, ``waited_s`` the wait in wall
    seconds, ``status_text`` the autopilot's latest STATUSTEXT since the command (may be empty)."""

    def __init__(self, robot_id: str, command: str, expected: str, observed: str, waited_s: float,
                 status_text: str = "") -> None:
        self.robot_id, self.command, self.expected, self.observed = robot_id, command, expected, observed
        self.waited_s, self.status_text = waited_s, status_text
        why = f" ({status_text})" if status_text else ""
        super().__init__(f"robot {robot_id!r}: {command}: acknowledged (MAV_RESULT_ACCEPTED) but no HEARTBEAT showed "
                         f"{expected} within {waited_s:g} s; the HEARTBEAT shows {observed}{why}")

    def __reduce__(self):  # picklable across Ray workers
        return (CommandNotConfirmed, (self.robot_id, self.command, self.expected, self.observed, self.waited_s,
                                      self.status_text))


class CommandNotAcknowledged(BackendError):
    """No COMMAND_ACK came for a command within its tries (MAVLink command protocol), e.g. every answer lost on
    a loaded link. A mode change or an arm whose effect the HEARTBEAT shows anyway is taken as done."""


def _log_level(severity: int) -> int:
    """The :mod:`logging` level of a MAV_SEVERITY (0 EMERGENCY .. 7 DEBUG)."""
    if severity <= M.MAV_SEVERITY_CRITICAL:
        return logging.CRITICAL
    return {M.MAV_SEVERITY_ERROR: logging.ERROR, M.MAV_SEVERITY_WARNING: logging.WARNING,
            M.MAV_SEVERITY_DEBUG: logging.DEBUG}.get(severity, logging.INFO)


def _enum_name(enum: str, value: int) -> str:
    e = M.enums.get(enum, {}).get(value)
    return e.name if e is not None else f"{enum} {value}"


def _f32(v: float | None) -> float | None:
    """Round a parameter to what a float32 MAVLink field carries; NaN/None stay None."""
    if v is None or v != v:
        return None
    return float32(float(v))


