"""Parameters (mavlink.io parameter protocol: PARAM_REQUEST_READ / PARAM_SET, answered by PARAM_VALUE) and the
vehicle's own speed limits set from the robot's ``limits``.

Why the vehicle's parameters: both autopilots fly their own speed unless told otherwise. ArduCopter flies GUIDED
and AUTO at ``WPNAV_SPEED`` (cm/s, range 20-2000; climb/descent ``WPNAV_SPEED_UP``/``WPNAV_SPEED_DN`` cm/s;
ArduCopter ``AC_WPNav`` parameter table) and re-initialises its navigation speed from ``WPNAV_SPEED`` on every
entry to AUTO, so MAV_CMD_DO_CHANGE_SPEED alone does not last. PX4 limits every position-controlled mode with
``MPC_XY_VEL_MAX`` (m/s) and flies missions at ``MPC_XY_CRUISE`` (m/s); vertically ``MPC_Z_VEL_MAX_UP`` /
``MPC_Z_VEL_MAX_DN`` (m/s), which PX4 itself applies to its automatic climb/descent speeds ("Ascent speed has
been constrained by max speed"; ``src/modules/mc_pos_control/multicopter_*_params.c``). PX4's take-off and
landing speeds (``MPC_TKO_SPEED``, ``MPC_LAND_SPEED``) are left alone: lowered to 0.5 m/s the SIH quadrotor
never left the ground (auto preflight disarm after 10 s). A parameter the firmware does not have gets no
PARAM_VALUE: it is reported (``param_unavailable`` event) and left out, never guessed.
"""
from __future__ import annotations

import math
import struct
import threading
import time
from typing import Any, Callable, Protocol

from aerodaas.backends.base import BackendError
from aerodaas.backends.mavlink._common import M, _f32
from aerodaas.backends.mavlink.clock import VehicleClock
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink.telemetry import VehicleTelemetry
from aerodaas.backends.mavlink.speed_margin import MIN_STEP_MPS, EstimatorSpeedMargin, SpeedCap

#: PX4's horizontal limits are ``limits.max_speed`` less this margin (m/s), and never below half of it (see
#: :func:`px4_speed_limit`). PX4's velocity loop holds its *estimate* at MPC_XY_VEL_MAX, and each GPS fusion step
#: of EKF2 moves that estimate (and the position) by a jolt that the loop then flies off: an overshoot in m/s, not
#: a fraction of the speed. On SIH (its EKF2 then told SIH's IMU noise) the reported speed peaked 0.15-0.24 m/s
#: above MPC_XY_VEL_MAX 0.3 in five runs (0.45-0.54 m/s at max_speed 0.5, for 0.2-0.5 s), and the distance flown
#: over 4 s stayed within MPC_XY_VEL_MAX + 0.13 m/s. On 30 m legs (2026-11-23): at MPC_XY_VEL_MAX 1.5 the
#: reported peak was +0.04 m/s and the distance flown over 1 s +0.19 m/s; with this rule, max_speed 3.0 (2.75)
#: peaked at 2.64 reported and 2.92 m/s over 1 s, max_speed 1.0 (0.75) at 0.92 and 1.01 m/s.
_PX4_SPEED_MARGIN_MPS = 0.25


def px4_speed_limit(max_speed: float) -> float:
    """PX4's ``MPC_XY_VEL_MAX`` / ``MPC_XY_CRUISE`` (m/s) for a robot whose ``limits.max_speed`` is ``max_speed``
    m/s: ``max(max_speed - 0.25, max_speed / 2)`` (0.25 m/s at 0.5, 2.75 m/s at 3). The margin is measured
    overshoot (:data:`_PX4_SPEED_MARGIN_MPS`); ArduCopter needs none (it flies WPNAV_SPEED within the limit)."""
    return max(float(max_speed) - _PX4_SPEED_MARGIN_MPS, speed_floor(max_speed))


def speed_floor(max_speed: float) -> float:
    """The lowest horizontal limit (m/s) the backend gives a vehicle whose ``limits.max_speed`` is ``max_speed``
    m/s: half of it (PX4's rule above, and the in-flight margin's floor: a vehicle held to a crawl cannot hold its
    position against its own estimator either)."""
    return 0.5 * float(max_speed)


#: how long (wall seconds, at most ``command_timeout_s``) one round of PARAM_REQUEST_READ waits for its answers
_PARAM_READ_WAIT_S = 0.6


class ParameterProtocol:
    """The MAVLink parameter protocol with one vehicle (mavlink.io: PARAM_REQUEST_READ / PARAM_SET, answered by
    PARAM_VALUE), a concern object of :class:`~aerodaas.backends.mavlink.MavlinkBackend`.

    It is given the ``link`` (sending, the link check, the vehicle's system and component id once connected, and
    its autopilot: PX4's integers travel bytewise). ``settings``: ``command_timeout_s`` and ``command_retries``. It
    registers :meth:`on_param_value` with the link for every PARAM_VALUE (the I/O thread); reads and writes wait on
    them (the control thread).

    State: the latest value per parameter (name -> float), a condition notified on each, and the user's values of
    the parameters AeroDaaS changed (:meth:`remember_original`, put back by :meth:`restore`)."""

    def __init__(self, robot_id: str, settings: Any, *, link: MavlinkLink) -> None:
        self.robot_id, self._settings, self._link = robot_id, settings, link
        self._values: dict[str, float] = {}
        self._cv = threading.Condition()
        self._originals: dict[str, float] = {}
        link.handle("PARAM_VALUE", self.on_param_value)

    def _is_px4(self) -> bool:
        return self._link.autopilot == "px4"

    @property
    def changed(self) -> list[str]:
        """The parameters whose user's value is kept for :meth:`restore`, sorted."""
        return sorted(self._originals)

    def remember_original(self, name: str, value: float) -> None:
        """Keep ``value`` as the user's value of ``name`` (the first one given wins) for :meth:`restore`."""
        self._originals.setdefault(name, value)

    def on_param_value(self, msg: Any) -> None:
        """A PARAM_VALUE from the vehicle: its value (PX4's integers decoded bytewise) is the parameter's latest."""
        name = msg.param_id.decode(errors="replace") if isinstance(msg.param_id, bytes) else str(msg.param_id)
        name = name.rstrip("\x00")
        value = float(msg.param_value)
        if msg.param_type in (M.MAV_PARAM_TYPE_INT32, M.MAV_PARAM_TYPE_UINT32, M.MAV_PARAM_TYPE_INT16,
                              M.MAV_PARAM_TYPE_UINT16, M.MAV_PARAM_TYPE_INT8, M.MAV_PARAM_TYPE_UINT8) \
                and self._is_px4():
            # PX4 sends integers bytewise in the float field (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE)
            value = float(struct.unpack("<i", struct.pack("<f", msg.param_value))[0])
        with self._cv:
            self._values[name] = value
            self._cv.notify_all()

    def read(self, names: list[str], wait_s: float | None = None) -> dict[str, float]:
        """Read ``names`` with PARAM_REQUEST_READ (all at once, re-asked once for those still missing), waiting up
        to ``wait_s`` wall seconds per round (default min(``command_timeout_s``, 0.6)). Returns the values that
        came (floats, in the parameter's own unit); a name without answer is absent (the firmware lacks it).
        Raises LinkLost."""
        self._link.check_link("read parameters")
        wait = min(self._settings.command_timeout_s, _PARAM_READ_WAIT_S) if wait_s is None else wait_s
        with self._cv:
            for n in names:
                self._values.pop(n, None)
        for _ in range(2):
            missing = [n for n in names if n not in self._values]
            if not missing:
                break
            sysid, compid = self._link.target
            for n in missing:
                self._link.send(lambda mav, n=n: mav.param_request_read_send(sysid, compid, n.encode(), -1))
            end = time.monotonic() + wait
            with self._cv:
                while any(n not in self._values for n in missing) and time.monotonic() < end:
                    self._cv.wait(timeout=max(0.0, min(0.05, end - time.monotonic())))
        return {n: self._values[n] for n in names if n in self._values}

    def set(self, name: str, value: float, wait_s: float | None = None, integer: bool = False) -> float:
        """PARAM_SET ``name`` = ``value`` and wait for the PARAM_VALUE echo (re-sent up to ``command_retries``
        times, each try ``command_timeout_s``). ``integer``: an INT32 parameter; PX4 refuses a PARAM_SET whose type
        is not the parameter's ("param types mismatch", src/modules/mavlink/mavlink_parameters.cpp) and takes the
        integer bytewise in the float field (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE); ArduPilot converts
        the REAL32 value to the parameter's own type (AP_Param), so it always gets REAL32. Returns the value the
        vehicle reports, which may differ (the firmware clamps to its range). Raises BackendError when no echo
        comes, LinkLost."""
        self._link.check_link(f"set parameter {name}")
        retries = self._settings.command_retries
        wait = self._settings.command_timeout_s if wait_s is None else wait_s
        if integer and self._is_px4():
            v32 = struct.unpack("<f", struct.pack("<i", int(round(value))))[0]
            ptype = M.MAV_PARAM_TYPE_INT32
        else:
            v32, ptype = _f32(value), M.MAV_PARAM_TYPE_REAL32
        for _ in range(retries + 1):
            with self._cv:
                self._values.pop(name, None)
            sysid, compid = self._link.target
            self._link.send(lambda mav: mav.param_set_send(sysid, compid, name.encode(), v32, ptype))
            end = time.monotonic() + wait
            with self._cv:
                while name not in self._values and time.monotonic() < end:
                    self._cv.wait(timeout=max(0.0, min(0.05, end - time.monotonic())))
                if name in self._values:
                    return self._values[name]
            self._link.check_link(f"set parameter {name}")
        raise BackendError(f"robot {self.robot_id!r}: set parameter {name}: no PARAM_VALUE after "
                           f"{retries + 1} tries of {wait:g} s")

    def restore(self, event: Callable[..., None]) -> dict[str, float]:
        """Put back the user's values kept by :meth:`remember_original` (best effort: a parameter whose echo does
        not come is reported through ``event`` as ``param_restore_failed``; ``params_restored`` names what was put
        back). Returns what was restored. Never raises."""
        done = {}
        for name, value in list(self._originals.items()):
            try:
                done[name] = self.set(name, value)
                self._originals.pop(name, None)
            except Exception as e:  # noqa: BLE001 - closing: report and go on
                event("param_restore_failed", name=name, error=str(e))
        if done:
            event("params_restored", **{k: round(v, 3) for k, v in done.items()})
        return done


class SpeedCommander(Protocol):
    """The guided control's speed command (offboard.py :class:`~aerodaas.backends.mavlink.offboard.OffboardControl`):
    whether a DO_CHANGE_SPEED is in force (ArduPilot's GUIDED flies it, not WPNAV_SPEED), and sending it again at the
    limit now in force (raises as :meth:`CommandProtocol.command_long`)."""

    @property
    def speed_commanded(self) -> bool: ...

    def resend_speed(self) -> None: ...


class SpeedLimits:
    """The vehicle's own speed limits for the robot's ``limits`` (see the module docstring), set over the parameter
    protocol, and lowered in flight when the vehicle's estimator needs more margin
    (:mod:`~aerodaas.backends.mavlink.speed_margin`).

    It is given its collaborators: ``limits`` (the robot's :class:`~aerodaas.config.Limits`), ``params`` (the
    parameter protocol), ``link`` (the autopilot, whether the link is up), ``clock`` (vehicle seconds),
    ``telemetry`` (whether the vehicle is in the air; the speed limits follow its GNSS speeds,
    :meth:`VehicleTelemetry.notify_gnss_speed`), ``event`` (records a backend event) and ``lock`` (the backend's
    lock, which guards the margin's samples: the I/O thread adds them). :meth:`resend_speed` is handed the
    :class:`SpeedCommander` whose DO_CHANGE_SPEED it sends again.

    State: whether the limits were applied, the estimator's measured margin and the cap it asks for, the worker
    thread lowering the limit (:attr:`worker`) and its retry schedule, and a DO_CHANGE_SPEED still to be re-sent."""

    def __init__(self, robot_id: str, limits: Any, *, params: ParameterProtocol, link: MavlinkLink,
                 clock: VehicleClock, telemetry: VehicleTelemetry, event: Callable[..., None],
                 lock: threading.RLock) -> None:
        self.robot_id, self.limits = robot_id, limits
        self._params, self._link, self._clock, self._telemetry = params, link, clock, telemetry
        self._event, self._lock = event, lock
        telemetry.notify_gnss_speed(self)
        self._limits_applied = False
        self._speed_margin = EstimatorSpeedMargin()
        self._speed_cap: SpeedCap | None = None  # lowered for the estimator's margin (None: the autopilot's rule)
        self._speed_check_t = 0.0  # vehicle time of the next check
        self._speed_worker: threading.Thread | None = None  # lowering the vehicle's limit (_lower_speed_limit)
        self._speed_retry_t = 0.0  # vehicle time before which no new try after a failed one
        self._speed_backoff_s = 1.0
        self._speed_resend = False  # the lowered limit's DO_CHANGE_SPEED is still to be sent (ArduPilot)
        self._unholdable_reported = False

    @property
    def worker(self) -> threading.Thread | None:
        """The thread lowering the vehicle's limit (:meth:`update`), if one was started."""
        return self._speed_worker

    def xy_speed_cap(self) -> float:
        """The horizontal speed (m/s) the vehicle is limited to for the robot's ``limits.max_speed``: the
        autopilot's rule (ArduCopter ``max_speed``; PX4 :func:`px4_speed_limit`), lowered in flight when the
        vehicle's estimator needs more margin than that (:mod:`~aerodaas.backends.mavlink.speed_margin`)."""
        cap = self._speed_cap
        default = self._default_speed_cap()
        return min(default, cap.cap_mps) if cap is not None else default

    def _default_speed_cap(self) -> float:
        """The autopilot's rule for ``limits.max_speed`` (m/s): ArduCopter the limit itself, PX4
        :func:`px4_speed_limit`."""
        xy = float(self.limits.max_speed)
        return px4_speed_limit(xy) if self._link.autopilot == "px4" else xy

    def _limit_parameters(self) -> dict[str, float]:
        """The parameters that carry the robot's ``limits`` on this autopilot, in the firmware's units (see the
        module docstring): ArduCopter cm/s, PX4 m/s; horizontally :meth:`xy_speed_cap`."""
        xy, z = self.xy_speed_cap(), float(self.limits.max_vertical_speed)
        if self._link.autopilot == "ardupilot":
            return {"WPNAV_SPEED": max(20.0, xy * 100.0), "WPNAV_SPEED_UP": max(10.0, z * 100.0),
                    "WPNAV_SPEED_DN": max(10.0, z * 100.0)}
        # PX4's velocity estimate jolts above its setpoint on every GPS fusion correction: a margin (see above)
        return {"MPC_XY_VEL_MAX": xy, "MPC_XY_CRUISE": xy}

    def on_gnss_speed(self, gnss_speed_mps: float, est_hspeed: float, est_steady: bool) -> None:
        """A GPS_RAW_INT ground speed (m/s, 3-D fix): with the vehicle in the air, its estimated horizontal speed
        ``est_hspeed`` (m/s) steady (``est_steady``: telemetry.py ``_set_velocity``) and at least half the applied
        limit (where the limit binds: a hovering vehicle's GNSS noise is no overshoot of it), one sample of GNSS
        minus estimated horizontal speed for the speed margin. Caller: the I/O thread, holding the backend's
        lock."""
        with self._lock:
            if est_steady and est_hspeed >= 0.5 * self.xy_speed_cap() and self._telemetry.in_air:
                self._speed_margin.add(gnss_speed_mps, est_hspeed)

    def update(self) -> None:
        """Every 2 vehicle seconds (from the backend's ``step``, the drone's clock thread; it never blocks there): a limit
        that cannot hold (``max_speed`` too small for the measured margin) is reported once
        (``speed_limit_unholdable``); when the margin needs a limit at least
        :data:`~aerodaas.backends.mavlink.speed_margin.MIN_STEP_MPS` below the applied one and the backend set the
        vehicle's limits (``set_speed_limits``), a worker thread sets it on the vehicle (:meth:`_lower_speed_limit`;
        one at a time, not while the link is lost, after a failure again only 2 -> 4 -> ... 30 vehicle seconds
        later). Only ever lowered within a connection. Never raises."""
        if self._clock.t < self._speed_check_t:
            return
        self._speed_check_t = self._clock.t + 2.0
        xy = float(self.limits.max_speed)
        with self._lock:
            cap: SpeedCap = self._speed_margin.cap(xy, self._default_speed_cap(), floor=speed_floor(xy))
        if not cap.holdable and not self._unholdable_reported:
            self._unholdable_reported = True
            self._event("speed_limit_unholdable", max_speed=xy, margin_mps=cap.margin_mps, samples=cap.samples,
                        cap_mps=round(cap.cap_mps, 3),
                        reason="the vehicle's estimator lets it fly this much faster than its estimate (GNSS, p99): "
                               "its limit cannot keep it within max_speed + 10 %")
        worker = self._speed_worker
        if (not self._limits_applied or not self._link.link_ok or (worker is not None and worker.is_alive())
                or self._clock.t < self._speed_retry_t or cap.cap_mps > self.xy_speed_cap() - MIN_STEP_MPS):
            return
        self._speed_worker = threading.Thread(target=self._lower_speed_limit, args=(cap,), daemon=True,
                                              name=f"speed-limit-{self.robot_id}")
        self._speed_worker.start()

    def _lower_speed_limit(self, cap: SpeedCap) -> None:
        """Worker thread of :meth:`update`: set the vehicle's limits to ``cap`` and read them back
        (``speed_margin`` event); on ArduPilot with a DO_CHANGE_SPEED in force (GUIDED flies it, not WPNAV_SPEED)
        :meth:`resend_speed` sends it again at the new limit from the drone's thread. A failed write:
        ``speed_limit_update_failed``, the limit stays as it was, the next try waits twice as long (at most 30
        vehicle s). Never raises."""
        before, self._speed_cap = self._speed_cap, cap
        try:
            verified = self.apply()
        except Exception as e:  # noqa: BLE001 - in flight: report, keep flying at the applied limit, retry later
            self._speed_cap = before
            self._speed_backoff_s = min(30.0, 2.0 * self._speed_backoff_s)
            self._speed_retry_t = self._clock.t + self._speed_backoff_s
            self._event("speed_limit_update_failed", cap_mps=round(cap.cap_mps, 3), error=str(e),
                        retry_in_s=self._speed_backoff_s)
            return
        self._speed_backoff_s = 1.0
        self._event("speed_margin", margin_mps=cap.margin_mps, samples=cap.samples, cap_mps=round(cap.cap_mps, 3),
                    max_speed=float(self.limits.max_speed), **{k: round(v, 3) for k, v in verified.items()})
        # ArduCopter's GUIDED leg flies the DO_CHANGE_SPEED it was given: the drone's thread sends it again at the
        # new limit (commands are not sent from this thread: one command exchange at a time)
        self._speed_resend = self._link.autopilot == "ardupilot"

    def resend_speed(self, speed: SpeedCommander) -> None:
        """From the backend's ``step`` (the drone's thread) after the limit was lowered: ArduPilot's DO_CHANGE_SPEED
        again when ``speed`` has one in force, for the speed last asked (offboard.py ``resend_speed`` caps it at the
        new limit); a refusal or timeout is reported (``speed_command_failed``; WPNAV_SPEED holds from the next mode
        change). Never raises."""
        if not self._speed_resend:
            return
        self._speed_resend = False
        if not speed.speed_commanded:
            return
        try:
            speed.resend_speed()
        except Exception as e:  # noqa: BLE001 - reported; flying on
            self._event("speed_command_failed", cap_mps=round(self.xy_speed_cap(), 3), error=str(e))

    def apply(self) -> dict[str, float]:
        """Make the vehicle's own speed limits the robot's ``limits`` (``max_speed``, ``max_vertical_speed``):
        read each parameter (keeping the user's value for the backend's ``restore_parameters``), set the ones that allow
        more than the limit, and read every one back (PARAM_VALUE). Returns the verified values (firmware units). Raises BackendError when a value
        read back differs from what was set (beyond float32 rounding) or the firmware never echoes a
        PARAM_SET; LinkLost."""
        want = self._limit_parameters()
        have = self._params.read(list(want))
        for name in want:
            if name not in have:
                self._event("param_unavailable", name=name)
        changed = {}
        for name, value in have.items():
            target = want[name]
            if abs(value - target) <= 1e-3 * max(1.0, abs(target)):
                continue
            self._params.remember_original(name, value)
            changed[name] = target
        for name, target in changed.items():
            got = self._params.set(name, target)
            if not math.isclose(got, target, rel_tol=1e-4, abs_tol=1e-4):
                raise BackendError(f"robot {self.robot_id!r}: speed limit {name}: set {target:g}, the vehicle "
                                   f"reports {got:g}")
        verified = self._params.read(list(have)) if changed else have
        for name, target in changed.items():
            if name in verified and not math.isclose(verified[name], target, rel_tol=1e-4, abs_tol=1e-4):
                raise BackendError(f"robot {self.robot_id!r}: speed limit {name}: set {target:g}, read back "
                                   f"{verified[name]:g}")
        self._limits_applied = True
        self._event("speed_limits", **{k: round(v, 3) for k, v in verified.items()}, changed=sorted(changed))
        return verified
