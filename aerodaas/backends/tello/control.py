"""Tello flight control (:class:`TelloControl`): the motion worker (one manoeuvre at a time, started by
:meth:`TelloControl.takeoff`, :meth:`~TelloControl.goto`, :meth:`~TelloControl.land`; pre-emption with ``stop``;
retries that re-check the state instead of re-sending a relative ``go``) and the flight commands the
:class:`~aerodaas.backends.base.VehicleBackend` contract names."""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from aerodaas.backends.base import BackendError, CommandRefused, LinkLost
from aerodaas.backends.tello.link import TelloLink, _Cancelled
from aerodaas.backends.tello.protocol import GO_MAX_CM, GO_MIN_CM, GO_SPEED_CM, go_command

#: wall seconds a manoeuvre waits, after the sticks were released, for a state packet showing the Tello at rest
#: (velocity fields 0 dm/s, yaw unchanged); the body-frame ``go`` offset is computed from that pose
SETTLE_S = 1.5


@dataclass
class _Motion:
    """A manoeuvre run by the motion worker: its name, cancel flag, and how its first command went."""

    name: str
    cancel: threading.Event = field(default_factory=threading.Event)
    settled: threading.Event = field(default_factory=threading.Event)  # first command answered (or failed)
    lock: threading.Lock = field(default_factory=threading.Lock)
    returned: bool = False  # the caller has returned: later errors become events
    error: BackendError | None = None
    thread: threading.Thread | None = None


class TelloControl:
    """The flight commands of one Tello (see the module docstring), a concern object of
    :class:`~aerodaas.backends.tello.backend.TelloBackend`: ``cfg`` (:class:`~aerodaas.config.TelloConfig`),
    ``limits`` (the robot's :class:`~aerodaas.config.Limits`: speeds for ``go`` and the sticks) and ``link`` (the
    :class:`~aerodaas.backends.tello.link.TelloLink` it commands and whose state it reads). State: the running
    manoeuvre and whether the vehicle counts as armed (:attr:`armed`)."""

    def __init__(self, robot_id: str, cfg: Any, limits: Any, link: TelloLink) -> None:
        self.robot_id, self.cfg, self.limits, self._link = robot_id, cfg, limits, link
        self._motion: _Motion | None = None
        self._armed = False

    @property
    def armed(self) -> bool:
        """Marked armed (:meth:`arm`, a take-off) and not disarmed or landed since."""
        return self._armed

    def cancel(self) -> None:
        """Cancel the running manoeuvre's worker (closing: nothing is sent)."""
        m = self._motion
        if m is not None:
            m.cancel.set()

    # ------------------------------------------------------------------ motion worker
    def _motion_timeout(self, distance_m: float, speed_mps: float) -> float:
        return self.cfg.command_timeout_s + 1.5 * distance_m / max(speed_mps, 0.1)

    def _start_motion(self, name: str, plan: Callable[[_Motion], None]) -> None:
        self._require_link(name)
        # a manoeuvre that was stopped, or sticks released, leave the Tello braking: the plan waits for rest first
        released = time.monotonic() if self._preempt() else None
        if any(self._link.sticks):  # else the keep-alive would resume the old velocity after the manoeuvre
            self._link.sticks = (0, 0, 0, 0)
            self._link.send_rc(self._link.sticks)
            released = time.monotonic()
        m = _Motion(name)

        def run() -> None:
            try:
                if released is not None:
                    self._await_rest(m, released)
                plan(m)
            except _Cancelled:
                pass
            except BackendError as e:
                with m.lock:
                    if not m.returned:  # the caller raises it
                        m.error = e
                    else:
                        self._link.event("command_failed", command=name, error=str(e))
            finally:
                m.settled.set()

        m.thread = threading.Thread(target=run, name=f"tello-{self.robot_id}-{name}", daemon=True)
        self._motion = m
        self._link.manoeuvre = m.thread
        m.thread.start()
        # the caller hears a refusal of the first command, also when it comes after the wait for rest
        m.settled.wait(self.cfg.accept_window_s + (SETTLE_S if released is not None else 0.0))
        with m.lock:
            m.returned = True
            if m.error is not None:
                raise m.error

    def _await_rest(self, m: _Motion, since: float) -> None:
        """After the sticks were released or a manoeuvre stopped (at monotonic ``since``): wait up to :data:`SETTLE_S` for a state packet
        received after it that shows the Tello at rest, so that a ``go`` offset (body frame, from the current
        yaw and dead-reckoned position) is computed from where it stopped, not from a pose it is braking out of.
        Goes on after the bound (the ``go`` then starts from the latest estimate); raises _Cancelled if pre-empted."""
        end = since + SETTLE_S
        while time.monotonic() < end:
            if m.cancel.is_set():
                raise _Cancelled()
            rest = self._link.rest_at
            if rest is not None and rest > since:
                return
            time.sleep(0.01)
        self._link.stats["settle_timeouts"] += 1

    def _motion_step(self, m: _Motion, cmd: str, timeout_s: float) -> str | None:
        """One manoeuvre command: the reply, or None when it went unanswered (the plan re-checks the state)."""
        try:
            reply = self._link.transact(cmd, timeout_s, retries=0, cancel=m.cancel)
        except LinkLost:
            raise
        except BackendError:
            return None
        if reply.lower() != "ok":
            self._link.last_status = reply
            raise CommandRefused(self.robot_id, cmd, reply)
        m.settled.set()
        return reply

    def _retry_until(self, m: _Motion, cmd: str, timeout_s: float, done: Callable[[], bool]) -> None:
        for attempt in range(self.cfg.command_retries + 1):
            if attempt:
                self._link.stats["retries"] += 1
            if self._motion_step(m, cmd, timeout_s) is not None or done():
                return
        raise BackendError(f"robot {self.robot_id!r}: {cmd}: no reply after {self.cfg.command_retries + 1} tries "
                           f"and the state shows it did not happen")

    def _preempt(self) -> bool:
        """Stop the running manoeuvre (cancel its worker, ``stop``); True if one was running."""
        m = self._motion
        if m is None or m.thread is None or not m.thread.is_alive():
            return False
        m.cancel.set()
        m.thread.join(timeout=2.0)
        self._link.expect_ok("stop", self._link.transact("stop", self.cfg.command_timeout_s, self.cfg.command_retries))
        return True

    def _in_air(self) -> bool:
        return self._link.height_cm >= 10.0

    def _require_link(self, command: str) -> None:
        if not self._link.connected:
            raise LinkLost(f"robot {self.robot_id!r}: {command}: not connected (call connect() first)")
        if not self._link.link_ok:
            raise LinkLost(f"robot {self.robot_id!r}: {command}: link lost (no state packet for "
                           f"{self.cfg.state_timeout_s} s)")

    @property
    def busy(self) -> bool:
        """True while a manoeuvre (takeoff, go, land) is being executed."""
        m = self._motion
        return m is not None and m.thread is not None and m.thread.is_alive()

    # ------------------------------------------------------------------ control
    def arm(self) -> None:
        """The Tello has no arming step (``takeoff`` starts the motors): checks the link and the battery
        reported in the state packets, then marks the vehicle armed. Raises LinkLost / CommandRefused."""
        self._require_link("arm")
        if self._link.battery_pct <= 10:
            raise CommandRefused(self.robot_id, "arm", "battery low", f"battery {self._link.battery_pct:.0f} %")
        self._armed = True

    def disarm(self) -> None:
        """Marks the vehicle disarmed; refused while it is in the air (use :meth:`land` or :meth:`emergency`)."""
        if self._in_air():
            raise CommandRefused(self.robot_id, "disarm", "in air", f"height {self._link.height_cm:.0f} cm")
        self._armed = False

    def takeoff(self, altitude_m: float) -> None:
        """``takeoff`` (the Tello climbs to about 0.8 m), then ``up``/``down`` to ``altitude_m`` metres above the
        take-off point. Raises CommandRefused (the Tello's reply) or LinkLost; ValueError for a bad altitude."""
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"takeoff: altitude_m must be a positive number of metres, got {altitude_m!r}")
        c = self.cfg

        def plan(m: _Motion) -> None:
            if not self._in_air():
                self._retry_until(m, "takeoff", c.command_timeout_s + 3.0, lambda: self._in_air())
            self._armed = True
            self._climb_to(m, altitude_m)

        self._start_motion("takeoff", plan)

    def _climb_to(self, m: _Motion, altitude_m: float) -> None:
        for _ in range(int(altitude_m * 100) // GO_MAX_CM + 3):
            dz = int(round(altitude_m * 100 - self._link.height_cm))
            if abs(dz) < GO_MIN_CM:
                return
            step = min(abs(dz), GO_MAX_CM)
            word = "up" if dz > 0 else "down"
            self._motion_step(m, f"{word} {step}", self._motion_timeout(step / 100, self.limits.max_vertical_speed))

    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        """Fly to ``target_enu`` (ENU metres from home) with body-frame ``go x y z speed`` commands computed from
        the dead-reckoned position: legs longer than 5 m are cut into ``go`` chunks along the straight line; the
        remaining offset is recomputed after each one (so a lost reply is recovered without flying twice). When a
        ``go`` is answered ``ok``, the horizontal position is set to its start plus the commanded offset (the
        Tello's own estimate, finer than our integral of its 0.1 m/s state velocities).
        ``speed`` m/s (None: ``limits.max_speed``), clipped to the SDK's 0.1-1.0 m/s. Stops once every axis is
        within the 20 cm the ``go`` command cannot resolve. Raises CommandRefused / LinkLost / ValueError."""
        tgt = np.asarray([float(v) for v in target_enu], float)
        if tgt.shape != (3,) or not np.all(np.isfinite(tgt)):
            raise ValueError(f"goto: target_enu must be 3 finite ENU metres, got {target_enu!r}")
        v = self.limits.max_speed if speed is None else float(speed)
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"goto: speed must be a positive number of m/s, got {speed!r}")
        speed_cm = int(np.clip(round(v * 100), *GO_SPEED_CM))

        def plan(m: _Motion) -> None:
            unanswered = 0
            start = self._link.position
            max_legs = int(np.linalg.norm(tgt - start) * 100 // GO_MAX_CM) + 4
            for _ in range(max_legs):
                p0, yaw0 = self._link.position, math.radians(self._link.yaw)
                cmd = self._go_command(tgt, speed_cm)
                if cmd is None:
                    return
                fwd, left, up = (int(x) / 100.0 for x in cmd.split()[1:4])
                dist = math.sqrt(fwd * fwd + left * left + up * up)
                if self._motion_step(m, cmd, self._motion_timeout(dist, speed_cm / 100.0)) is not None:
                    # 'ok' = the Tello's own (optical-flow) estimate says it flew the commanded offset: trust it
                    # over our integral of velocities quantised to 0.1 m/s
                    self._link.correct_horizontal(p0[0] + fwd * math.cos(yaw0) - left * math.sin(yaw0),
                                                  p0[1] + fwd * math.sin(yaw0) + left * math.cos(yaw0))
                else:
                    unanswered += 1
                    self._link.stats["retries"] += 1
                    if unanswered > self.cfg.command_retries:
                        raise BackendError(f"robot {self.robot_id!r}: {cmd}: no reply after "
                                           f"{unanswered} tries")
            if self._go_command(tgt, speed_cm) is not None:
                raise BackendError(f"robot {self.robot_id!r}: goto {tgt.round(2).tolist()}: still "
                                   f"{np.linalg.norm(tgt - self._link.position):.2f} m away after {max_legs} go commands")

        self._start_motion("goto", plan)

    def _go_command(self, tgt: np.ndarray, speed_cm: int) -> str | None:
        return go_command(tgt - self._link.position, self._link.yaw, speed_cm)

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        """``rc a b c d`` from the ENU velocity (m/s) rotated into the body frame with the current yaw: sticks
        are ``100 * v / limits.max_speed`` (right, forward), ``100 * v_up / limits.max_vertical_speed`` and
        ``-100 * yaw_rate / limits.max_yaw_rate`` (the Tello's yaw stick is clockwise-positive), clipped to
        -100..100. Stops a running manoeuvre first. Raises LinkLost / ValueError."""
        v = [float(c) for c in v_enu]
        if len(v) != 3 or not all(math.isfinite(c) for c in v) or not math.isfinite(yaw_rate_dps):
            raise ValueError(f"set_velocity: v_enu must be 3 finite m/s values and yaw_rate_dps finite, "
                             f"got {v_enu!r}, {yaw_rate_dps!r}")
        self._require_link("set_velocity")
        self._preempt()
        yaw = math.radians(self._link.yaw)
        fwd = v[0] * math.cos(yaw) + v[1] * math.sin(yaw)
        right = v[0] * math.sin(yaw) - v[1] * math.cos(yaw)
        lim = self.limits

        def stick(x: float, full: float) -> int:
            return int(np.clip(round(100.0 * x / full), -100, 100))

        self._link.sticks = (stick(right, lim.max_speed), stick(fwd, lim.max_speed),
                        stick(v[2], lim.max_vertical_speed), stick(-yaw_rate_dps, lim.max_yaw_rate))
        self._link.send_rc(self._link.sticks)

    def hold(self) -> None:
        """Hover: ``stop`` when a manoeuvre is running, else ``rc 0 0 0 0``. Raises LinkLost when the link is
        down (after still sending the command)."""
        self._link.sticks = (0, 0, 0, 0)
        if self.busy:
            self._preempt()
        else:
            self._link.send_rc(self._link.sticks)
        if not self._link.link_ok:
            raise LinkLost(f"robot {self.robot_id!r}: hold: link lost (no state packet for "
                           f"{self.cfg.state_timeout_s} s)")

    def land(self) -> None:
        """``land`` where the vehicle is (re-sent only while the state still shows it in the air).
        Raises CommandRefused / LinkLost."""
        self._link.sticks = (0, 0, 0, 0)

        def plan(m: _Motion) -> None:
            self._retry_until(m, "land", self._motion_timeout(self._link.height_cm / 100.0, 0.5), lambda: not self._in_air())
            self._armed = False

        self._start_motion("land", plan)

    def return_to_launch(self) -> bool:
        """False: the Tello has no return mode (the drone flies home with :meth:`goto` and lands)."""
        return False

    def emergency(self) -> None:
        """``emergency``: stop the motors at once (the Tello falls). Sent without waiting for a manoeuvre."""
        m = self._motion
        if m is not None:
            m.cancel.set()
        self._link.send("emergency")
        self._armed = False
