"""Position/velocity targets (SET_POSITION_TARGET_GLOBAL_INT / LOCAL_NED, POSITION_TARGET_TYPEMASK): ArduPilot GUIDED and PX4 OFFBOARD."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.constants import _GLOBAL_FRAMES
from aerodaas.emulators.mavlink.modes import FlightModes
from aerodaas.emulators.mavlink.motion import Motion
from aerodaas.emulators.mavlink.state import EmulatorState

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link

M = mavlink

__all__ = ["GuidedTargets"]


class GuidedTargets:
    """The SET_POSITION_TARGET_* handlers: every target is logged in ``state`` (:attr:`.state.EmulatorState.setpoint_log`,
    which PX4's OFFBOARD stream check reads; a returning stream ends PX4's offboard-loss fallback through ``modes``)
    and flown by ``motion`` when the firmware would. Not locked: the vehicle calls it under its lock."""

    def __init__(self, state: EmulatorState, modes: FlightModes, motion: Motion) -> None:
        self.state, self.modes, self.motion = state, modes, motion

    def note_setpoint(self) -> None:
        """A target arrived now (vehicle time)."""
        st = self.state
        st.last_setpoint_t = st.t
        st.setpoint_log.append(st.t)
        self.modes.offboard_signal_back()

    def apply_target(self, pos_enu: np.ndarray | None, vel_enu: np.ndarray | None,
                     yaw_rate_dps: float | None) -> None:
        """A position (ENU m from the EKF origin) and/or velocity (ENU m/s) target with a yaw rate (deg/s, ENU
        counter-clockwise; None: none): noted, kept for PX4's next OFFBOARD entry, and flown
        (:meth:`.motion.Motion.fly_target`)."""
        self.note_setpoint()
        self.state.last_target = (pos_enu, vel_enu, yaw_rate_dps)
        self.motion.fly_target(pos_enu, vel_enu, yaw_rate_dps)

    def _decode_target(self, msg: Any, pos: np.ndarray | None) -> None:
        """A SET_POSITION_TARGET_* ``msg`` whose position (ENU m, None when the type mask ignores it) is ``pos``."""
        tm = msg.type_mask
        pos_ign = (tm & 0b111) == 0b111
        vel_ign = (tm & 0b111000) == 0b111000
        yaw_rate = None if tm & M.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE else -math.degrees(msg.yaw_rate)
        if not pos_ign:
            vel = None if vel_ign else np.array([msg.vy, msg.vx, -msg.vz])
            self.apply_target(pos, vel, yaw_rate)
        elif not vel_ign:
            self.apply_target(None, np.array([msg.vy, msg.vx, -msg.vz]), yaw_rate)
        else:
            self.note_setpoint()

    @staticmethod
    def _position_ignored(msg: Any) -> bool:
        return (msg.type_mask & 0b111) == 0b111

    def on_set_position_target_global_int(self, link: _Link, msg: Any) -> None:
        """SET_POSITION_TARGET_GLOBAL_INT in a global frame (others are ignored)."""
        frame = msg.coordinate_frame
        if frame not in _GLOBAL_FRAMES:
            return
        pos = None if self._position_ignored(msg) else \
            self.state.global_to_enu(msg.lat_int / 1e7, msg.lon_int / 1e7, msg.alt, frame)
        self._decode_target(msg, pos)

    def on_set_position_target_local_ned(self, link: _Link, msg: Any) -> None:
        """SET_POSITION_TARGET_LOCAL_NED in LOCAL_NED (from the EKF origin) or LOCAL_OFFSET_NED (from the vehicle)."""
        if msg.coordinate_frame not in (M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_LOCAL_OFFSET_NED):
            return
        if self._position_ignored(msg):
            pos = None
        elif msg.coordinate_frame == M.MAV_FRAME_LOCAL_NED:
            pos = np.array([msg.y, msg.x, -msg.z])  # NED from the EKF origin
        else:
            pos = self.state.veh.state.position + np.array([msg.y, msg.x, -msg.z])
        self._decode_target(msg, pos)
