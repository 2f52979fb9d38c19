"""Guided/offboard control: position and velocity targets streamed in ArduPilot GUIDED / PX4 OFFBOARD
(SET_POSITION_TARGET_GLOBAL_INT / _LOCAL_NED), and the hand-over to the autopilot's own hold/land/return modes."""
from __future__ import annotations

import math
import time
from typing import Sequence

import numpy as np

from ...geo import enu_to_geodetic
from ..base import LinkLost
from ._common import M, CommandNotConfirmed, POSITION_ONLY_MASK, POSITION_VELOCITY_MASK, VELOCITY_ONLY_MASK


class OffboardMixin:
    """Part of :class:`~aerodaas.backends.mavlink.MavlinkBackend` (see its docstring for the shared state)."""

    def _carrot(self, sp: tuple) -> tuple:
        """A speed-capped goto as the position setpoint to send now: ``("carrot", start_enu, target_enu, speed m/s,
        vehicle t0)`` moves from start towards target at ``speed`` metres per vehicle second."""
        _, start, target, speed, t0 = sp
        delta = target - start
        length = float(np.linalg.norm(delta))
        frac = 1.0 if length < 1e-6 else min(1.0, speed * max(0.0, self.t - t0) / length)
        p = start + delta * frac
        v = delta / length * speed if frac < 1.0 else np.zeros(3)  # velocity feed-forward, ENU
        g = enu_to_geodetic(float(p[0]), float(p[1]), 0.0, self.home)
        return ("posvel", int(round(g.lat * 1e7)), int(round(g.lon * 1e7)), float(p[2]), *self.enu_to_ned(v))

    def _send_setpoint(self, sp: tuple) -> None:
        try:
            if sp[0] == "carrot":
                sp = self._carrot(sp)
            if sp[0] == "pos":
                _, lat_i, lon_i, alt = sp
                self._send(lambda mav: mav.set_position_target_global_int_send(
                    self._boot_ms_out(), self._sysid, self._compid, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                    POSITION_ONLY_MASK, lat_i, lon_i, alt, 0, 0, 0, 0, 0, 0, 0, 0))
            elif sp[0] == "posvel":
                _, lat_i, lon_i, alt, vn, ve, vd = sp
                self._send(lambda mav: mav.set_position_target_global_int_send(
                    self._boot_ms_out(), self._sysid, self._compid, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                    POSITION_VELOCITY_MASK, lat_i, lon_i, alt, vn, ve, vd, 0, 0, 0, 0, 0))
            else:
                _, vn, ve, vd, yaw_rate = sp
                self._send(lambda mav: mav.set_position_target_local_ned_send(
                    self._boot_ms_out(), self._sysid, self._compid, M.MAV_FRAME_LOCAL_NED, VELOCITY_ONLY_MASK,
                    0, 0, 0, vn, ve, vd, 0, 0, 0, 0, yaw_rate))
            self._sp_sent += 1
        except LinkLost:
            pass

    def _guided_mode(self) -> str:
        return "OFFBOARD" if self.autopilot == "px4" else "GUIDED"

    def _enter_guided(self, sp: tuple) -> None:
        """Make ``sp`` the active target and fly it: ArduPilot GUIDED (mode first, then the target), PX4 OFFBOARD
        (stream first, then the mode switch, which PX4 refuses without a stream)."""
        guided = self._guided_mode()
        if self.autopilot == "px4":
            with self._lock:
                self._setpoint = sp
                self._sp_next = 0.0
            self._send_setpoint(sp)
            if self._mode != guided:
                start, sent0 = time.monotonic(), self._sp_sent
                # PX4 wants the stream running before the switch: at least 3 setpoints and 0.3 s of vehicle time
                while (self._sp_sent - sent0 < 3 or (time.monotonic() - start) * self._ratio < 0.3) \
                        and time.monotonic() - start < 2.0:
                    time.sleep(0.005)
                self.set_mode(guided)
        else:
            if self._mode != guided:
                self.set_mode(guided)
            with self._lock:
                self._setpoint = sp
                self._sp_next = time.monotonic() + 1.0 / (self.cfg.setpoint_rate_hz * self._ratio)
            self._send_setpoint(sp)

    def _stop_setpoints(self) -> None:
        with self._lock:
            self._setpoint = None

    def _change_speed(self, speed: float | None) -> None:
        if speed == self._speed_cmd:
            return
        self.command_long("change speed", M.MAV_CMD_DO_CHANGE_SPEED, 1, -2 if speed is None else speed, -1)
        self._speed_cmd = speed

    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        """Fly to ``target_enu`` (ENU metres from home) with SET_POSITION_TARGET_GLOBAL_INT
        (MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, position-only type mask), re-sent by the I/O thread. A ``speed`` cap
        (m/s): ArduPilot gets MAV_CMD_DO_CHANGE_SPEED (ground speed; GUIDED honours it); PX4 OFFBOARD flies
        position setpoints at its own velocity limit (DO_CHANGE_SPEED is a navigator/mission command), so the
        streamed setpoint itself moves from here towards the target at ``speed`` per vehicle second, with that
        velocity as feed-forward (position + velocity type mask).
        Raises ValueError for a non-finite target or a non-positive speed."""
        self._require_navigable("goto")
        x, y, z = (float(v) for v in target_enu)
        if not all(math.isfinite(v) for v in (x, y, z)):
            raise ValueError(f"goto target_enu must be finite metres, got {tuple(target_enu)!r}")
        if speed is not None and not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"goto speed must be a positive number of m/s or None, got {speed!r}")
        self._check_link("goto")
        if self.autopilot == "px4" and speed is not None:
            self._enter_guided(("carrot", self.position, np.array([x, y, z]), float(speed), self.t))
            return
        g = enu_to_geodetic(x, y, 0.0, self.home)
        sp = ("pos", int(round(g.lat * 1e7)), int(round(g.lon * 1e7)), z)
        if self.autopilot == "ardupilot":
            self._change_speed(speed)
        self._enter_guided(sp)

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        """Hold ENU velocity ``v_enu`` (m/s) and yaw rate (deg/s, counter-clockwise) with
        SET_POSITION_TARGET_LOCAL_NED (MAV_FRAME_LOCAL_NED, velocity + yaw-rate type mask; NED = (v_north, v_east,
        -v_up), yaw rate clockwise rad/s), re-sent at ``setpoint_rate_hz`` vehicle time."""
        self._require_navigable("set_velocity")
        ve, vn, vu = (float(v) for v in v_enu)
        if not all(math.isfinite(v) for v in (ve, vn, vu, yaw_rate_dps)):
            raise ValueError(f"set_velocity needs finite m/s and deg/s, got {tuple(v_enu)!r}, {yaw_rate_dps!r}")
        self._check_link("set_velocity")
        self._enter_guided(("vel", vn, ve, -vu, -math.radians(yaw_rate_dps)))

    def hold(self) -> None:
        """Hover here: in GUIDED/OFFBOARD a position target at the current position; otherwise the autopilot's
        hold mode (ArduPilot LOITER, PX4 LOITER/Hold). On the ground it only stops the target stream."""
        self._require_navigable("hold")
        self._check_link("hold")
        if not self.in_air:
            self._stop_setpoints()
            return
        if self._mode == self._guided_mode():
            p = self.position
            self.goto((p[0], p[1], p[2]))
        else:
            self._autopilot_mode("LOITER")

    def land(self) -> None:
        """LAND mode (ArduPilot LAND, PX4 AUTO.LAND): descend and land here; both disarm once landed. Raises as
        :meth:`set_mode`."""
        self._require_navigable("land")
        self._autopilot_mode("LAND")

    def return_to_launch(self) -> bool:
        """RTL mode (ArduPilot RTL, PX4 AUTO.RTL): the autopilot climbs to its return altitude, flies home, lands
        and disarms. Returns True. Raises as :meth:`set_mode`."""
        self._require_navigable("return_to_launch")
        self._autopilot_mode("RTL")
        return True

    def _autopilot_mode(self, name: str) -> None:
        """Hand the vehicle to one of the autopilot's own modes and stop streaming our targets. A refused mode
        change keeps the stream (the vehicle stays where our last target holds it); one the autopilot accepted but
        whose HEARTBEAT has not shown it yet (CommandNotConfirmed) stops it too, so a late switch is not pulled
        back by our setpoints."""
        try:
            self.set_mode(name)
        except CommandNotConfirmed:
            self._stop_setpoints()
            raise
        self._stop_setpoints()

