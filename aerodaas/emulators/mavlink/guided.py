"""Position/velocity targets (SET_POSITION_TARGET_GLOBAL_INT / LOCAL_NED, POSITION_TARGET_TYPEMASK): ArduPilot GUIDED and PX4 OFFBOARD."""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.constants import _GLOBAL_FRAMES


from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link

M = mavlink


class GuidedMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator` (state lives there)."""

    def _target_allowed(self) -> bool:
        if self.px4:
            return True  # PX4 records every setpoint; it acts on them in OFFBOARD only
        return self.mode == "GUIDED"

    def _note_setpoint(self) -> None:
        self.last_setpoint_t = self.t
        self.setpoint_log.append(self.t)
        self._offboard_signal_back()

    def _apply_target(self, pos_enu: np.ndarray | None, vel_enu: np.ndarray | None, yaw_rate_dps: float | None,
                      note: bool = True) -> None:
        if note:
            self._note_setpoint()
            self._last_target = (pos_enu, vel_enu, yaw_rate_dps)
        if not self._target_allowed():
            return
        s = self.veh.state
        if self.px4 and self.mode != "OFFBOARD":
            return
        if not s.armed:
            return
        if not self.px4 and not s.in_air and self.takeoff_alt is None:
            return  # ArduPilot ignores guided targets until it has taken off
        self.posvel = None
        if pos_enu is not None and vel_enu is not None:  # position with velocity feed-forward
            self.velocity_deadline = None
            self.takeoff_alt = None
            self.posvel = (np.asarray(pos_enu, float), np.asarray(vel_enu, float))
            self._track_posvel()
        elif pos_enu is not None:
            self.velocity_deadline = None
            self.takeoff_alt = None
            self._goto_enu(pos_enu)
        elif vel_enu is not None:
            self.takeoff_alt = None
            self.veh.set_velocity(tuple(float(v) for v in vel_enu), float(yaw_rate_dps or 0.0))
            if not self.px4:
                self.velocity_deadline = self.t + 3.0

    def _track_posvel(self) -> None:
        """Position + velocity target: the autopilots' position loop, v = v_ff + Kp (p_sp - p) (PX4 MPC_XY_P
        0.95, ArduPilot PSC_POSXY_P 1.0), re-evaluated every physics step."""
        pos, vel = self.posvel
        kp = 0.95 if self.px4 else 1.0
        v = vel + kp * (pos - self.veh.state.position)
        self.veh.set_velocity(tuple(float(c) for c in v), 0.0)

    def _decode_target(self, msg: Any, pos_fn: Callable[[], np.ndarray]) -> None:
        tm = msg.type_mask
        pos_ign = (tm & 0b111) == 0b111
        vel_ign = (tm & 0b111000) == 0b111000
        yaw_rate = None if tm & M.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE else -math.degrees(msg.yaw_rate)
        if not pos_ign:
            vel = None if vel_ign else np.array([msg.vy, msg.vx, -msg.vz])
            self._apply_target(pos_fn(), vel, yaw_rate)
        elif not vel_ign:
            self._apply_target(None, np.array([msg.vy, msg.vx, -msg.vz]), yaw_rate)
        else:
            self._note_setpoint()

    def _on_set_position_target_global_int(self, link: _Link, msg: Any) -> None:
        frame = msg.coordinate_frame
        if frame not in _GLOBAL_FRAMES:
            return
        self._decode_target(msg, lambda: self._global_to_enu(msg.lat_int / 1e7, msg.lon_int / 1e7, msg.alt, frame))

    def _on_set_position_target_local_ned(self, link: _Link, msg: Any) -> None:
        if msg.coordinate_frame not in (M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_LOCAL_OFFSET_NED):
            return
        if msg.coordinate_frame == M.MAV_FRAME_LOCAL_NED:
            pos = lambda: np.array([msg.y, msg.x, -msg.z])  # noqa: E731 - NED from the EKF origin
        else:
            pos = lambda: self.veh.state.position + np.array([msg.y, msg.x, -msg.z])  # noqa: E731
        self._decode_target(msg, pos)
