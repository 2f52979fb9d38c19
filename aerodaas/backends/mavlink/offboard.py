"""Guided/offboard control: position and velocity targets streamed in ArduPilot GUIDED / PX4 OFFBOARD
(SET_POSITION_TARGET_GLOBAL_INT / _LOCAL_NED), and the hand-over to the autopilot's own hold/land/return modes. A
concern object of :class:`~aerodaas.backends.mavlink.MavlinkBackend` (:class:`OffboardControl`), its command group
``guidance`` (:class:`~aerodaas.backends.base.Guidance`)."""
from __future__ import annotations

import math
import threading
import time
from typing import Any, Callable, Sequence

import numpy as np

from aerodaas.model.geo import enu_to_geodetic
from aerodaas.backends.base import LinkLost, VehicleBackend
from aerodaas.backends.mavlink.clock import VehicleClock
from aerodaas.backends.mavlink.command import CommandProtocol
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink.params import SpeedLimits
from aerodaas.backends.mavlink.signing import SignedOnly
from aerodaas.backends.mavlink.telemetry import VehicleTelemetry
from aerodaas.backends.mavlink._common import M, CommandNotConfirmed, log, POSITION_ONLY_MASK, POSITION_VELOCITY_MASK, VELOCITY_ONLY_MASK


#: lowest target height (metres above the take-off point) goto sends to an armed vehicle
_MIN_TARGET_HEIGHT_M = 0.5
#: how far (metres along the leg) a speed-capped PX4 setpoint may run ahead of the vehicle (see _carrot). It bounds
#: how far a vehicle can fall behind the setpoint's schedule and then catch up: PX4's velocity loop flies its
#: *estimate* at MPC_XY_VEL_MAX, and SIH's estimate ran 0.1-0.2 m/s below the truth for seconds at a time, so a
#: vehicle 0.5 m behind caught up at 0.42 m/s over 4 s (MPC_XY_VEL_MAX 0.25: 0.25 + (0.5 + 0.2) / 4 s); 0.25 m
#: bounds the 4 s average near MPC_XY_VEL_MAX + 0.1 m/s
_CARROT_LEAD_M = 0.25


class OffboardControl:
    """Guided control of one vehicle: the position/velocity target streamed to it, the speed-capped goto, the
    offboard-loss watch, the last DO_CHANGE_SPEED, the hand-over to the autopilot's own modes and the safe end.

    It is given its collaborators: ``link`` (sending, the link check, the vehicle's ids, the autopilot, its mode,
    armed flag, latest HEARTBEAT time, mode changes seen and ``autopilot_failsafe`` events not yet handed out),
    ``clock`` (vehicle seconds and their rate, the vehicle's latest time_boot_ms and when it was received, our
    time_boot_ms for the setpoints we send), ``telemetry`` (home, position, altitude reference, in the air),
    ``speed_limits`` (the horizontal speed limit), ``commands`` (the command protocol: modes, DO_CHANGE_SPEED),
    ``signed`` (:class:`SignedOnly`: ``mavlink.require_signing`` for targets), ``event`` (records a backend event)
    and ``lock`` (the backend's lock, which guards the target state: the I/O
    thread sends the stream, :meth:`send_due`; it registers with the link, :meth:`MavlinkLink.serve_setpoints`).
    ``settings``: ``setpoint_rate_hz``, ``on_close``, ``safe_end_timeout_s``.

    State: the active setpoint and its stream (when the next is due, how many were sent, the last one's wall and
    vehicle time, a stall seen), the speed-capped goto's progress, PX4's offboard-loss timeout
    (:attr:`loss_timeout_s`), when the stream was stopped as stalled, the last DO_CHANGE_SPEED asked and sent, and
    whether we are in control (:attr:`in_control`: we armed it or sent it targets or a mission, so
    :meth:`safe_end` is ours)."""

    def __init__(self, robot_id: str, settings: Any, *, link: MavlinkLink, clock: VehicleClock,
                 telemetry: VehicleTelemetry, speed_limits: SpeedLimits, commands: CommandProtocol,
                 signed: SignedOnly, event: Callable[..., None], lock: threading.RLock) -> None:
        self.robot_id, self._settings, self._signed = robot_id, settings, signed
        self._link, self._clock, self._telemetry, self._speed_limits = link, clock, telemetry, speed_limits
        self._commands, self._event, self._lock = commands, event, lock
        self._in_control = False  # we armed it or sent it targets/missions: safe_end() is ours to do
        self._setpoint: tuple | None = None
        self._carrot_sp: tuple | None = None  # the speed-capped goto being flown, its progress (m) and time (s)
        self._carrot_s = self._carrot_t = 0.0
        self._sp_sent = 0
        self._sp_next = 0.0
        # the running stream's last setpoint: wall time, the vehicle's time_boot_ms then (None: no stream running),
        # and when a stall of it was first seen (_stream_may_go_on)
        self._sp_wall, self._sp_boot_ms, self._stall_seen = 0.0, None, None
        self._loss_s = 1.0  # PX4's offboard-loss timeout COM_OF_LOSS_T (vehicle seconds), read at connect
        self._offboard_lost_at: float | None = None  # wall time the stream was stopped as stalled
        self._speed_cmd: tuple | None = None  # (m/s, mode change count) of the last DO_CHANGE_SPEED
        self._speed_asked: float | None = None  # the speed of the last DO_CHANGE_SPEED asked (None: the limit)

        link.serve_setpoints(self)

    @property
    def in_control(self) -> bool:
        """We armed the vehicle or sent it targets or a mission: bringing it down at the end is ours to do."""
        return self._in_control

    def take_control(self) -> None:
        """We command the vehicle now (armed it, targets, a mission): :attr:`in_control`."""
        self._in_control = True

    @property
    def loss_timeout_s(self) -> float:
        """PX4's offboard-loss timeout ``COM_OF_LOSS_T`` (vehicle seconds; 1 until read at connect)."""
        return self._loss_s

    @loss_timeout_s.setter
    def loss_timeout_s(self, seconds: float) -> None:
        self._loss_s = float(seconds)

    @property
    def setpoint(self) -> tuple | None:
        """The active target streamed by the I/O thread (None: no stream). Caller holds the backend's lock."""
        return self._setpoint

    @property
    def speed_commanded(self) -> bool:
        """A DO_CHANGE_SPEED was sent (ArduPilot's GUIDED flies it, not WPNAV_SPEED)."""
        return self._speed_cmd is not None

    def send_due(self, sp: tuple, now: float) -> None:
        """The I/O thread at monotonic ``now`` with the active target ``sp``: send it when the next of the stream is
        due (``setpoint_rate_hz`` in the vehicle's time; ArduPilot's position targets at 1 Hz) and the stream may
        go on (:meth:`_stream_may_go_on`)."""
        if now >= self._sp_next and self._stream_may_go_on(now):
            rate = self._settings.setpoint_rate_hz if sp[0] == "vel" or self._link.autopilot == "px4" else 1.0
            self._sp_next = now + max(0.004, 1.0 / (rate * self._clock.ratio))
            self._send_setpoint(sp)

    def resend_speed(self) -> None:
        """ArduPilot's DO_CHANGE_SPEED again for the speed last asked (:meth:`_change_speed` caps it at the limit
        now in force). Raises as :meth:`CommandProtocol.command_long`."""
        self._change_speed(self._speed_asked)

    def _carrot(self, sp: tuple) -> tuple:
        """A speed-capped goto as the position setpoint to send now: ``("carrot", start_enu, target_enu, speed m/s,
        vehicle t0)`` moves from start towards target at ``speed`` metres per vehicle second, with that velocity as
        feed-forward, but never more than :data:`_CARROT_LEAD_M` ahead of the vehicle's own progress along the
        leg: a vehicle that fell behind (PX4 SIH's velocity estimate lags its true speed by up to 0.6 m/s) is not
        pulled into a sprint to catch up, and one that ran ahead is pulled back by PX4's position loop."""
        _, start, target, speed, t0 = sp
        delta = target - start
        length = float(np.linalg.norm(delta))
        with self._lock:
            now = self._clock.t
            if self._carrot_sp is not sp:  # a new leg
                self._carrot_sp, self._carrot_s, self._carrot_t = sp, 0.0, max(now, t0)
            if length < 1e-6:
                s_now = length
            else:
                unit = delta / length
                along = float(np.dot(self._telemetry.position - start, unit))  # the vehicle's progress, metres
                step = speed * max(0.0, now - self._carrot_t)
                s_now = min(length, max(self._carrot_s, min(self._carrot_s + step, along + _CARROT_LEAD_M)))
            self._carrot_s, self._carrot_t = s_now, now
        frac = 1.0 if length < 1e-6 else s_now / length
        p = start + delta * frac
        v = delta / length * speed if frac < 1.0 else np.zeros(3)  # velocity feed-forward, ENU
        lat_i, lon_i, alt, frame = self._global_target(float(p[0]), float(p[1]), float(p[2]))
        return ("posvel", lat_i, lon_i, alt, frame, *VehicleBackend.enu_to_ned(v))

    def _global_target(self, x: float, y: float, z: float) -> tuple[int, int, float, int]:
        """ENU metres -> (lat 1e-7 deg, lon 1e-7 deg, altitude m, MAV_FRAME) for SET_POSITION_TARGET_GLOBAL_INT:
        once the altitude reference is fixed (arming), MAV_FRAME_GLOBAL_INT with the AMSL altitude reference +
        ``z`` (a frame that does not move with PX4's re-estimated home); before, relative to home."""
        g = enu_to_geodetic(x, y, 0.0, self._telemetry.home)
        lat_i, lon_i = int(round(g.lat * 1e7)), int(round(g.lon * 1e7))
        if self._telemetry.altitude_reference is not None:
            return lat_i, lon_i, self._telemetry.altitude_reference + z, M.MAV_FRAME_GLOBAL_INT
        return lat_i, lon_i, z, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT

    def _stream_may_go_on(self, now: float) -> bool:
        """May the I/O thread send the next setpoint of the running stream (PX4)? PX4 leaves OFFBOARD when no setpoint
        came for ``COM_OF_LOSS_T`` seconds of its own clock (its offboard-loss failsafe), and when the stream comes
        back it ends that failsafe by itself and flies OFFBOARD again (failsafe.cpp ``checkModeFallback``: the
        fallback lasts while ``offboard_control_signal_lost``; the pilot's mode stays OFFBOARD). So a stream that
        stopped for longer, because this process stalled or the link was cut while the firmware ran, must not
        resume: that would undo the autopilot's failsafe before we have even seen it (``mavlink.on_failsafe``).

        After a stall (no setpoint for half of ``COM_OF_LOSS_T`` in wall time at the vehicle's speed-up) this waits
        for a ``time_boot_ms`` sample received after the link's socket was found empty once the stall was seen
        (``LinkPort.live_since``: the backlog is read, this is the vehicle's clock now; a backlog judged by when we
        processed it let a stale clock through, in emulation of a SIGSTOPped drone actor). When the vehicle's clock ran more than ``COM_OF_LOSS_T`` since our last setpoint, the stream
        stops (event ``offboard_stream_stalled``): the autopilot's own mode change that follows, or came while we
        stalled, is its failsafe (link.py ``_check_failsafe``). A firmware stopped with us (SITL under a debugger)
        shows no such gap and the stream goes on. ArduPilot has no such failsafe in GUIDED (always True)."""
        if self._link.autopilot != "px4":
            return True
        with self._lock:  # the caller's thread may stop or replace the stream meanwhile (stop, goto)
            sp_boot, sp = self._sp_boot_ms, self._setpoint
            if sp_boot is None or sp is None:
                return True
            limit = self._loss_s
            if (now - self._sp_wall) * self._clock.ratio > 0.5 * limit:
                if self._stall_seen is None:
                    self._stall_seen = now
                if self._clock.live_since <= self._stall_seen:
                    return False  # still the backlog of the stall: not yet the vehicle's state of now
            self._stall_seen = None
            gap_s = (self._clock.boot_ms - sp_boot) / 1000.0
            if gap_s <= limit:
                return True
            self._setpoint = None
            self._sp_boot_ms = None
            self._offboard_lost_at = now
        self._event("offboard_stream_stalled", vehicle_s=round(gap_s, 3), limit_s=limit, mode=self._link.mode)
        log.warning("%s: no setpoint reached the vehicle for %.1f s of its clock (COM_OF_LOSS_T %.1f s): the stream "
                    "is not resumed; PX4's offboard-loss failsafe has the vehicle", self.robot_id, gap_s, limit)
        return False

    def _send_setpoint(self, sp: tuple) -> None:
        try:
            if sp[0] == "carrot":
                sp = self._carrot(sp)
            if sp[0] == "pos":
                _, lat_i, lon_i, alt, frame = sp
                self._link.send(lambda mav: mav.set_position_target_global_int_send(
                    self._clock.boot_ms_out(), *self._link.target, frame,
                    POSITION_ONLY_MASK, lat_i, lon_i, alt, 0, 0, 0, 0, 0, 0, 0, 0))
            elif sp[0] == "posvel":
                _, lat_i, lon_i, alt, frame, vn, ve, vd = sp
                self._link.send(lambda mav: mav.set_position_target_global_int_send(
                    self._clock.boot_ms_out(), *self._link.target, frame,
                    POSITION_VELOCITY_MASK, lat_i, lon_i, alt, vn, ve, vd, 0, 0, 0, 0, 0))
            else:
                _, vn, ve, vd, yaw_rate = sp
                self._link.send(lambda mav: mav.set_position_target_local_ned_send(
                    self._clock.boot_ms_out(), *self._link.target, M.MAV_FRAME_LOCAL_NED, VELOCITY_ONLY_MASK,
                    0, 0, 0, vn, ve, vd, 0, 0, 0, 0, yaw_rate))
            self._sp_sent += 1
            self._sp_wall, self._sp_boot_ms = time.monotonic(), self._clock.boot_ms
        except LinkLost:
            pass

    def _guided_mode(self) -> str:
        return "OFFBOARD" if self._link.autopilot == "px4" else "GUIDED"

    def _autopilot_has_it(self, command: str) -> bool:
        """Whether the autopilot has taken the vehicle in a way the caller has not yet been told of, so that
        ``command`` must not be sent (checked before any mode change, speed or target of goto/set_velocity, and again
        under the lock where the target is installed): an ``autopilot_failsafe`` event not yet handed out by
        :meth:`drain_events` (our next target or GUIDED/OFFBOARD switch would end its failsafe before the mission
        even knows), or a setpoint stream stopped by :meth:`_stream_may_go_on` whose outcome no HEARTBEAT has shown
        yet (waits at most for 1.5 vehicle seconds, one HEARTBEAT and a half, and 3 wall seconds). The caller learns
        the rest from its events (``mavlink.on_failsafe`` decides); a withheld command is recorded
        (``command_withheld``) and the drone re-issues its waypoint when no failsafe follows."""
        lost_at = self._offboard_lost_at
        if lost_at is not None:
            end = time.monotonic() + min(3.0, 1.5 / max(self._clock.ratio, 1e-3))
            while self._link.last_heartbeat <= lost_at and time.monotonic() < end and self._link.link_ok:
                time.sleep(0.01)
            with self._lock:
                fresh = self._link.last_heartbeat > lost_at
                if fresh and self._offboard_lost_at == lost_at:
                    self._offboard_lost_at = None
            if not fresh:
                return self._withheld(command, "offboard stream stalled; no HEARTBEAT since")
        if self._link.failsafe_undelivered:
            return self._withheld(command, f"autopilot failsafe {self._link.mode}")
        return False

    def _withheld(self, command: str, reason: str) -> bool:
        self._event("command_withheld", command=command, reason=reason)
        return True

    def _enter_guided(self, sp: tuple) -> None:
        """Make ``sp`` the active target and fly it: ArduPilot GUIDED (mode first, then the target), PX4 OFFBOARD
        (stream first, then the mode switch, which PX4 refuses without a stream). The callers (goto, set_velocity)
        have checked :meth:`_autopilot_has_it`; it is checked again here under the lock that installs the target,
        and before the mode switch (the I/O thread may have seen the autopilot's failsafe meanwhile)."""
        guided = self._guided_mode()
        self.take_control()
        if self._link.autopilot == "px4":
            with self._lock:
                withhold = bool(self._link.failsafe_undelivered or self._offboard_lost_at is not None)
                if not withhold:
                    if self._setpoint is None:
                        self._sp_boot_ms = None  # a new stream, not a gap in the old one
                        self._stall_seen = None
                    self._setpoint = sp
                    self._sp_next = 0.0  # sent by the I/O thread, after it read what the vehicle said (link.py)
            if withhold:
                self._withheld(sp[0], "autopilot failsafe meanwhile")
                return
            if self._link.mode != guided:
                start, sent0 = time.monotonic(), self._sp_sent
                # PX4 wants the stream running before the switch: at least 3 setpoints and 0.3 s of vehicle time
                while (self._sp_sent - sent0 < 3 or (time.monotonic() - start) * self._clock.ratio < 0.3) \
                        and time.monotonic() - start < 2.0:
                    time.sleep(0.005)
                with self._lock:  # the autopilot may have taken over while the stream started
                    ours = self._setpoint is sp and not self._link.failsafe_undelivered
                if not ours:
                    self._withheld(sp[0], f"stream stopped before the switch to {guided}")
                    return
                self._commands.set_mode(guided)
        else:
            if self._link.mode != guided:
                if self._link.failsafe_undelivered:
                    self._withheld(sp[0], f"autopilot failsafe {self._link.mode}")
                    return
                self._commands.set_mode(guided)
            with self._lock:
                self._setpoint = sp
                self._sp_next = time.monotonic() + 1.0 / (self._settings.setpoint_rate_hz * self._clock.ratio)
            self._send_setpoint(sp)

    def stop_quiet(self) -> None:
        """Stop streaming our targets, from the I/O thread (the autopilot took over: a failsafe)."""
        self._setpoint = None
        self._sp_boot_ms = None
        self._stall_seen = None

    def release(self) -> None:
        """Stop streaming targets and leave the vehicle to the mode it is in (the autopilot's failsafe): nothing is
        sent that could switch it back to GUIDED/OFFBOARD."""
        self.stop()

    def stop(self) -> None:
        """Stop streaming our targets (the caller's thread)."""
        with self._lock:
            self.stop_quiet()

    def _change_speed(self, speed: float | None) -> None:
        """ArduPilot: MAV_CMD_DO_CHANGE_SPEED (param1 1 = ground speed, param2 m/s, param3 -1 = throttle
        unchanged) to ``speed`` capped at :meth:`xy_speed_cap` (``limits.max_speed``, less any estimator margin
        measured in flight); no speed = the limit itself. Never -2 ("back to
        default"): ArduCopter answers it MAV_RESULT_DENIED (``Copter::do_change_speed`` accepts > 0 only). Sent
        again after every mode change (ArduCopter re-initialises its navigation speed from WPNAV_SPEED on mode
        entry). Raises as :meth:`command_long`."""
        self._speed_asked = speed
        limit = self._speed_limits.xy_speed_cap()
        value = limit if speed is None else min(float(speed), limit)
        key = (round(value, 3), self._link.mode_changes)
        if key == self._speed_cmd:
            return
        self._commands.command_long("change speed", M.MAV_CMD_DO_CHANGE_SPEED, 1, value, -1)
        self._speed_cmd = key

    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        """Fly to ``target_enu`` (ENU metres from home; height above the take-off point, at least 0.5 m once armed)
        with SET_POSITION_TARGET_GLOBAL_INT (MAV_FRAME_GLOBAL_INT at the altitude reference + height, see
        :meth:`_global_target`; position-only type mask), re-sent by the I/O thread. Speeds never exceed
        ``limits.max_speed`` (also the vehicle's own limit, params.py). A ``speed`` cap (m/s): ArduPilot gets
        MAV_CMD_DO_CHANGE_SPEED (ground speed; GUIDED honours it); PX4 OFFBOARD flies
        position setpoints at its own velocity limit (DO_CHANGE_SPEED is a navigator/mission command), so the
        streamed setpoint itself moves from here towards the target at ``speed`` per vehicle second, with that
        velocity as feed-forward (position + velocity type mask).
        Raises ValueError for a non-finite target or a non-positive speed; CredentialsRefused on an unsigned link
        when ``mavlink.require_signing`` (:class:`SignedOnly`)."""
        self._signed.require("goto")
        self._goto(target_enu, speed)

    def _goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        """:meth:`goto` without the signing check (a hold is never refused)."""
        x, y, z = (float(v) for v in target_enu)
        if not all(math.isfinite(v) for v in (x, y, z)):
            raise ValueError(f"goto target_enu must be finite metres, got {tuple(target_enu)!r}")
        if speed is not None and not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"goto speed must be a positive number of m/s or None, got {speed!r}")
        self._link.check_link("goto")
        if z < _MIN_TARGET_HEIGHT_M and self._link.armed:
            self._event("target_raised", asked_m=z, sent_m=_MIN_TARGET_HEIGHT_M,
                        reason="below the take-off point (only LAND goes lower)")
            z = _MIN_TARGET_HEIGHT_M
        if self._autopilot_has_it("goto"):  # before any mode change or speed command reaches the vehicle
            return
        if self._link.autopilot == "px4":
            # PX4 OFFBOARD: even at MPC_XY_VEL_MAX a 5 m position step overshoots it (0.64 m/s at 0.5 measured on
            # SIH); a setpoint moving at the speed, with it as feed-forward, is flown within the limit
            limit = self._speed_limits.xy_speed_cap()
            speed = limit if speed is None else min(float(speed), limit)
            self._enter_guided(("carrot", self._telemetry.position, np.array([x, y, z]), speed, self._clock.t))
            return
        sp = ("pos", *self._global_target(x, y, z))
        if self._link.autopilot == "ardupilot":
            if self._link.mode != "GUIDED":
                self._commands.set_mode("GUIDED")
            self._change_speed(speed)
        self._enter_guided(sp)

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        """Hold ENU velocity ``v_enu`` (m/s) and yaw rate (deg/s, counter-clockwise) with
        SET_POSITION_TARGET_LOCAL_NED (MAV_FRAME_LOCAL_NED, velocity + yaw-rate type mask; NED = (v_north, v_east,
        -v_up), yaw rate clockwise rad/s), re-sent at ``setpoint_rate_hz`` vehicle time. Raises ValueError for
        non-finite values; CredentialsRefused on an unsigned link when ``mavlink.require_signing``."""
        self._signed.require("set_velocity")
        ve, vn, vu = (float(v) for v in v_enu)
        if not all(math.isfinite(v) for v in (ve, vn, vu, yaw_rate_dps)):
            raise ValueError(f"set_velocity needs finite m/s and deg/s, got {tuple(v_enu)!r}, {yaw_rate_dps!r}")
        self._link.check_link("set_velocity")
        if self._autopilot_has_it("set_velocity"):
            return
        self._enter_guided(("vel", vn, ve, -vu, -math.radians(yaw_rate_dps)))

    def hold(self) -> None:
        """Hover here: in GUIDED/OFFBOARD a position target at the current position; otherwise the autopilot's
        hold mode (ArduPilot LOITER, PX4 LOITER/Hold). On the ground it only stops the target stream."""
        self._link.check_link("hold")
        if not self._telemetry.in_air:
            self.stop()
            return
        if self._link.mode == self._guided_mode():
            p = self._telemetry.position
            self._goto((p[0], p[1], p[2]))
        else:
            self._autopilot_mode("LOITER")

    def land(self) -> None:
        """LAND mode (ArduPilot LAND, PX4 AUTO.LAND): descend and land here; both disarm once landed. Raises as
        :meth:`set_mode`."""
        self._autopilot_mode("LAND")

    def return_to_launch(self) -> bool:
        """RTL mode (ArduPilot RTL, PX4 AUTO.RTL): the autopilot climbs to its return altitude, flies home, lands
        and disarms. Returns True. Raises as :meth:`set_mode`."""
        self._autopilot_mode("RTL")
        return True

    def _autopilot_mode(self, name: str) -> None:
        """Hand the vehicle to one of the autopilot's own modes and stop streaming our targets. A refused mode
        change keeps the stream (the vehicle stays where our last target holds it); one the autopilot accepted but
        whose HEARTBEAT has not shown it yet (CommandNotConfirmed) stops it too, so a late switch is not pulled
        back by our setpoints."""
        try:
            self._commands.set_mode(name)
        except CommandNotConfirmed:
            self.stop()
            raise
        self.stop()


    def safe_end(self) -> str:
        """Leave the vehicle safe before the link closes (a run's timeout, an error, Ctrl-C): in the air, hand it to
        the autopilot's LAND (or RTL: ``mavlink.on_close``) and wait, at most ``safe_end_timeout_s`` vehicle seconds,
        until it has landed and disarmed (both autopilots disarm by themselves after landing); armed on the ground in
        GUIDED/OFFBOARD, disarm. Never leaves it armed in GUIDED/OFFBOARD with nobody streaming targets: our stream
        stops only once the autopilot's own mode holds it. Returns what was done (``"nothing"``, ``"landed"``,
        ``"disarmed"``, ``"timeout"``, ``"link lost"``), also as a ``safe_end`` event. Raises BackendError /
        CommandRefused when LAND/RTL is refused."""
        if not self._link.armed or not self._in_control:
            return "nothing"  # disarmed, or armed by someone else and never commanded by us: not ours to end
        if not self._link.link_ok:
            self.stop()
            self._event("safe_end", result="link lost", mode=self._link.mode)
            return "link lost"
        if not self._telemetry.in_air:
            if self._link.mode in ("GUIDED", "OFFBOARD"):
                self.stop()
                self._commands.command_long("disarm", M.MAV_CMD_COMPONENT_ARM_DISARM, 0)
                self._event("safe_end", result="disarmed")
                return "disarmed"
            return "nothing"
        mode = "RTL" if self._settings.on_close == "rtl" else "LAND"
        if self._link.mode not in (mode, "LAND", "RTL"):
            self._autopilot_mode(mode)
        t0 = self._clock.t
        while self._link.armed and self._clock.t - t0 < self._settings.safe_end_timeout_s and self._link.link_ok:
            time.sleep(0.05)
        result = "landed" if not self._link.armed else ("link lost" if not self._link.link_ok else "timeout")
        self._event("safe_end", result=result, mode=mode, vehicle_s=round(self._clock.t - t0, 2))
        return result
