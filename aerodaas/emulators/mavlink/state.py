"""The emulated firmware's state, shared by its concern objects: :class:`EmulatorState` (the flight model, the
clock, the flight mode, home, the targets being flown, the firmware settings and the estimator's readiness read
from them) and :class:`MissionStore` (the stored mission, fence and rally items and where the mission run is).

Both hold data and answer questions about it; they send nothing (the concerns that act on them get the link).
Readiness as the firmware defines it is documented in :mod:`.arming`; frames in :meth:`EmulatorState.global_to_enu`.
"""
from __future__ import annotations

import math
import struct
import zlib
from collections import deque
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.model.geo import enu_to_geodetic, geodetic_to_enu
from aerodaas.model.types import GeoPoint
from aerodaas.emulators.mavlink.constants import (ARDUCOPTER_MODES, PX4_MODES, _AP_NEEDS_POSITION, _NAV_COMMANDS,
                                                 _PX4_MANUAL)
from aerodaas.emulators.mavlink.flavour import (AP_SENSORS, ARDUPILOT_PARAMS, EKF_NO_POSITION, EKF_POSITION,
                                               PX4_PARAMS, PX4_SENSORS)

if TYPE_CHECKING:
    from aerodaas.sim.vehicle import SimVehicle

M = mavlink

__all__ = ["EmulatorState", "MissionStore", "flavour_params"]


def _finite_at_least_0(name: str, value: float) -> float:
    """``value`` as a float; raises ValueError naming ``name`` unless it is a finite number >= 0."""
    if not (value >= 0 and math.isfinite(value)):
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    return float(value)


def flavour_params(autopilot: Literal["ardupilot", "px4"], system_id: int, speedup: float,
                   overrides: dict[str, float] | None) -> dict[str, float]:
    """The parameter table of the ``autopilot``'s firmware (:data:`.flavour.ARDUPILOT_PARAMS` /
    :data:`.flavour.PX4_PARAMS`, firmware units) with the system id and the ``overrides``. Raises ValueError naming
    an unknown parameter."""
    px4 = autopilot == "px4"
    params: dict[str, float] = dict(PX4_PARAMS if px4 else ARDUPILOT_PARAMS)
    params["MAV_SYS_ID" if px4 else "SYSID_THISMAV"] = float(system_id)
    if px4:
        # PX4 SITL stretches its loss timeouts by the simulation's speed factor, so that they stay the same in
        # wall time (ROMFS init.d-posix/rcS, "Adapt timeout parameters if simulation runs faster or slower than
        # realtime": COM_OF_LOSS_T = PX4_SIM_SPEED_FACTOR x 1.0 s); at 10x the unscaled 1 s was 0.1 s of wall
        # time, less than a loaded machine stalls a setpoint stream for
        params["COM_OF_LOSS_T"] = speedup * PX4_PARAMS["COM_OF_LOSS_T"]
    for k, v in (overrides or {}).items():
        if k not in params:
            raise ValueError(f"params: unknown {autopilot} parameter {k!r}; known: {sorted(params)}")
        params[k] = float(v)
    return params


class EmulatorState:
    """The state of one emulated vehicle: the flight model ``veh`` (ENU metres from the EKF ``origin``), the
    vehicle clock :attr:`t` (s), the firmware's ``params`` (firmware units, shared with the parameter protocol) and
    settings (see :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator`'s arguments: ``gps_lock_s``,
    ``ekf_gps_s``, ``estimate_speed_error_mps``, ``land_detect_s``, ``home_alt_drift_m``; ``params``: overrides of
    the flavour's parameters, :func:`flavour_params`). Raises ValueError naming the argument for a value out of
    range or an unknown parameter. Not locked: the vehicle uses it under its lock."""

    def __init__(self, autopilot: Literal["ardupilot", "px4"], veh: SimVehicle, origin: GeoPoint, *, system_id: int,
                 speedup: float, params: dict[str, float] | None, gps_lock_s: float, ekf_gps_s: float,
                 estimate_speed_error_mps: float, land_detect_s: float, home_alt_drift_m: float | None) -> None:
        self.autopilot, self.px4 = autopilot, autopilot == "px4"
        self.veh, self.origin = veh, origin
        self.gps_lock_s = gps_lock_s
        #: vehicle seconds from the GPS fix until the EKF fuses GPS (a position estimate); the firmware takes
        #: ~20 s (ArduCopter SITL) - shorter here so that tests stay fast
        self.ekf_gps_s = _finite_at_least_0("ekf_gps_s", ekf_gps_s)
        drift = (2.0 if self.px4 else 0.0) if home_alt_drift_m is None else float(home_alt_drift_m)
        if not (drift >= 0 and math.isfinite(drift)):
            raise ValueError(f"home_alt_drift_m must be a finite number >= 0, got {home_alt_drift_m!r}")
        #: bound (m) of PX4's in-flight home-altitude correction (COM_HOME_EN); 0 disables it
        self.home_alt_drift_m = drift
        #: the estimator reports the horizontal speed this much (m/s) below the true one, which GPS_RAW_INT carries:
        #: an estimator that lets the vehicle fly faster than its limit (stock PX4 SIH: 0.5 m/s at the p99,
        #: aerodaas.backends.mavlink.speed_margin); the physics flies the true speed at the vehicle's limit + this
        self.estimate_speed_error_mps = _finite_at_least_0("estimate_speed_error_mps", estimate_speed_error_mps)
        #: PX4: vehicle seconds after touchdown during which an unforced disarm is denied ("Disarming denied: not
        #: landed": its land detector has not confirmed the landing yet, commander Commander::disarm)
        self.land_detect_s = _finite_at_least_0("land_detect_s", land_detect_s)
        #: the firmware's parameters (name -> value in its units, in the order the parameter protocol indexes them)
        self.params = flavour_params(autopilot, system_id, speedup, params)
        #: a pre-arm check that fails with this text (test hook; None: none)
        self.prearm_failure: str | None = None
        self._init_flight()

    def _init_flight(self) -> None:
        """Clock, mode, home and the targets at boot."""
        self.t = 0.0  # vehicle seconds since the emulator started
        self.boot_ms0 = 73_421  # the autopilot booted a while before we count
        self.mode = "MANUAL" if self.px4 else "STABILIZE"
        self.home: GeoPoint | None = None
        self.home_enu = np.zeros(3)
        self.armed_at = 0.0
        self.landed_at: float | None = None
        self.took_off = False
        self.took_off_at: float | None = None
        self.speed: float | None = None  # DO_CHANGE_SPEED, m/s
        self.phase = ""  # RTL phase: climb / return / land
        self.last_setpoint_t = -1e9
        #: PX4: the mode its offboard-loss failsafe switched to, while the pilot's mode is still OFFBOARD (None: not
        #: in that failsafe); a setpoint stream that comes back ends it (modes.py)
        self.offboard_fallback: str | None = None
        #: vehicle time (s) of every position/velocity target received (the most recent 100 000)
        self.setpoint_log: deque[float] = deque(maxlen=100_000)
        #: (vehicle time s, mode name) of every mode change (the most recent 10 000)
        self.mode_log: deque[tuple[float, str]] = deque(maxlen=10_000)
        self.velocity_deadline: float | None = None  # ArduPilot GUIDED velocity timeout
        #: the last position/velocity target (ENU m or None, ENU m/s or None, yaw rate deg/s or None): PX4 acts on
        #: it when it enters OFFBOARD
        self.last_target: tuple[np.ndarray | None, np.ndarray | None, float | None] | None = None
        #: the active position + velocity feed-forward target (ENU m, ENU m/s)
        self.posvel: tuple[np.ndarray, np.ndarray] | None = None
        self.takeoff_alt: float | None = None  # metres above home being climbed to

    # ------------------------------------------------------------------ clock and mode
    def boot_ms(self) -> int:
        """``time_boot_ms`` now (ms since the autopilot booted, wraps at 2**32)."""
        return int(self.boot_ms0 + self.t * 1000.0) & 0xFFFFFFFF

    def set_mode(self, name: str) -> None:
        """The mode is ``name`` now, logged in :attr:`mode_log`."""
        self.mode = name
        self.mode_log.append((self.t, name))

    def mode_number(self) -> tuple[int, int]:
        """HEARTBEAT (base_mode, custom_mode): ArduCopter ``Mode::Number``; PX4 ``main << 16 | sub << 24``."""
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.veh.state.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        if self.px4:
            main, sub = PX4_MODES[self.mode]
            if self.mode in _PX4_MANUAL:
                base |= M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
            else:
                base |= M.MAV_MODE_FLAG_AUTO_ENABLED | M.MAV_MODE_FLAG_GUIDED_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
            return base, (main << 16) | (sub << 24)
        base |= M.MAV_MODE_FLAG_STABILIZE_ENABLED | M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if self.mode in ("AUTO", "RTL", "LOITER", "GUIDED", "CIRCLE", "POSHOLD", "BRAKE", "SMART_RTL"):
            base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        return base, ARDUCOPTER_MODES[self.mode]

    def offboard_stream_ok(self) -> bool:
        """PX4 enters OFFBOARD only with a live setpoint stream: the last one within COM_OF_LOSS_T and at least
        two in the last vehicle second."""
        log = self.setpoint_log
        recent = len(log) >= 2 and self.t - log[-2] <= 1.0
        return self.t - self.last_setpoint_t <= self.params["COM_OF_LOSS_T"] and recent

    # ------------------------------------------------------------------ estimator and readiness
    def fix_type(self) -> int:
        """GPS_FIX_TYPE: a 3-D fix from ``gps_lock_s`` vehicle seconds on, none before."""
        return M.GPS_FIX_TYPE_3D_FIX if self.t >= self.gps_lock_s else M.GPS_FIX_TYPE_NO_FIX

    def position_ok(self) -> bool:
        """The EKF has a horizontal position estimate (vehicle seconds ``gps_lock_s + ekf_gps_s``)."""
        return self.home is not None and self.t >= self.gps_lock_s + self.ekf_gps_s

    def prearm(self, mode: str | None = None) -> str | None:
        """The first failing pre-arm check for ``mode`` (default: the current one), in the autopilot's words
        without its prefix, or None (ArduCopter/AP_Arming_Copter.cpp mandatory_gps_checks; PX4 SIH's messages)."""
        mode = mode or self.mode
        if self.prearm_failure:
            return self.prearm_failure
        if self.px4:
            if self.fix_type() < 3:
                return "GPS fix too low"
            if not self.position_ok():
                return "heading estimate not stable"  # as seen on PX4 SIH before the EKF has converged
            return None
        if mode not in _AP_NEEDS_POSITION:
            return None
        if self.home is None:
            return "AHRS: waiting for home"
        if not self.position_ok():
            return "Need Position Estimate"
        return None

    def ekf_flags(self) -> int:
        """ArduPilot EKF_STATUS_REPORT.flags for the estimator's state."""
        return EKF_POSITION if self.position_ok() else EKF_NO_POSITION

    def sensors(self) -> tuple[int, int, int]:
        """SYS_STATUS (present, enabled, health) bit masks (MAV_SYS_STATUS_SENSOR; PX4 reports neither AHRS nor
        PREARM_CHECK as present, src/modules/mavlink/streams/SYS_STATUS.hpp)."""
        present = PX4_SENSORS if self.px4 else AP_SENSORS
        health = present
        if self.fix_type() < 3:
            health &= ~M.MAV_SYS_STATUS_SENSOR_GPS
        if not self.position_ok():
            health &= ~M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
        if self.px4:
            if self.prearm() is None:  # PX4 sets the pre-arm bit in health only
                health |= M.MAV_SYS_STATUS_PREARM_CHECK
            return present, present, health
        if self.home is None:
            health &= ~M.MAV_SYS_STATUS_AHRS
        if self.prearm() is not None:
            health &= ~M.MAV_SYS_STATUS_PREARM_CHECK
        return present, present, health

    # ------------------------------------------------------------------ position, frames, home
    def geo(self) -> GeoPoint:
        """The vehicle's position (WGS-84 degrees, metres AMSL)."""
        p = self.veh.state.position
        return enu_to_geodetic(float(p[0]), float(p[1]), float(p[2]), self.origin)

    def rel(self) -> np.ndarray:
        """The vehicle's position, ENU metres from home, shape (3,)."""
        return self.veh.state.position - self.home_enu

    def heading(self) -> float:
        """Compass heading in degrees (clockwise from north) from the simulator's ENU yaw."""
        return (90.0 - self.veh.state.yaw) % 360.0

    def estimated_velocity(self) -> np.ndarray:
        """The velocity the estimator reports (ENU m/s, shape (3,)): the true one with its horizontal speed lowered
        by ``estimate_speed_error_mps`` (GPS_RAW_INT keeps the true speed)."""
        v = np.array(self.veh.state.velocity, dtype=float)
        err = self.estimate_speed_error_mps
        h = float(np.hypot(v[0], v[1]))
        if err > 0 and h > 0:
            v[:2] *= max(0.0, h - err) / h
        return v

    def global_to_enu(self, lat: float, lon: float, alt: float, frame: int) -> np.ndarray:
        """Global position (deg, deg, m in MAV_FRAME ``frame``: AMSL for GLOBAL / GLOBAL_INT, else above home) ->
        ENU metres in the simulator's (EKF origin) frame, shape (3,)."""
        e, n, _ = geodetic_to_enu(lat, lon, self.origin.alt, self.origin)
        home_alt = self.home.alt if self.home is not None else self.origin.alt
        if frame in (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT):
            up = alt - self.origin.alt
        else:  # relative to home
            up = alt + (home_alt - self.origin.alt)
        return np.array([e, n, up])

    def set_home_here(self) -> None:
        """Home is where the vehicle is (on the ground: at most ground level). The caller announces it
        (HOME_POSITION)."""
        p = self.veh.state.position.copy()
        p[2] = min(p[2], 0.0) if not self.veh.state.in_air else p[2]
        self.home_enu = p
        self.home = enu_to_geodetic(float(p[0]), float(p[1]), float(p[2]), self.origin)

    def motors_lift(self) -> bool:
        """Whether the motors can climb. ArduPilot SITL scales the PWM of the motors in ``SIM_ENGINE_FAIL`` (a
        bitmask, bit 0: servo 1) by ``SIM_ENGINE_MUL`` (libraries/SITL/SITL.cpp, SIM_Aircraft.cpp); the emulator
        models only whether its quad's four motors together give at least half their thrust (a quadrotor hovers near
        half throttle): below that it does not climb. PX4: always (SIH has no such parameter)."""
        if self.px4:
            return True
        mask, mul = int(self.params["SIM_ENGINE_FAIL"]), self.params["SIM_ENGINE_MUL"]
        return sum(mul if mask >> i & 1 else 1.0 for i in range(4)) / 4.0 >= 0.5


class MissionStore:
    """The items a vehicle stores (as MISSION_ITEM_INT messages, wire sequence; ArduPilot's item 0 is home) and
    where its mission run is. ``px4``: PX4 numbers the first item 0, ArduPilot keeps home there."""

    def __init__(self, px4: bool) -> None:
        self.px4 = px4
        self.mission: list[Any] = []
        #: MAV_MISSION_TYPE_FENCE items, as MISSION_ITEM_INT (mission.py)
        self.fence_items: list[Any] = []
        #: MAV_MISSION_TYPE_RALLY items
        self.rally_items: list[Any] = []
        self.seq = 0  # the current item (MISSION_CURRENT)
        self.run_state = "idle"  # idle / wait_start / running / holding / done
        self.item_reached_at: float | None = None  # vehicle s of arrival at the current item
        self.item_started = False
        self.item_target = np.zeros(3)  # ENU target of the mission item being flown
        #: MISSION_ITEM_REACHED sequence numbers sent, in order
        self.reached_log: list[int] = []

    def mission_id(self) -> int:
        """The stored mission's plan id (:mod:`aerodaas.missionfile.plan_ids`): PX4's is a CRC32 of its items
        (0 without items), so a mission that replaces the stored one has another id; ArduPilot gives none (0)."""
        if not self.px4 or not self.mission:
            return 0
        crc = 0
        for it in self.mission:
            crc = zlib.crc32(struct.pack("<HBBffffiif", it.command, it.frame, it.autocontinue, it.param1, it.param2,
                                         it.param3, it.param4, it.x, it.y, it.z), crc)
        return crc or 1

    def nav_items(self) -> list[int]:
        """Sequence numbers of the navigation items (ArduPilot's home item 0 excluded)."""
        first = 0 if self.px4 else 1
        return [i for i in range(first, len(self.mission)) if self.mission[i].command in _NAV_COMMANDS]

    def starts_with_takeoff(self) -> bool:
        """Whether the first navigation item is a NAV_TAKEOFF."""
        nav = self.nav_items()
        return bool(nav) and self.mission[nav[0]].command == M.MAV_CMD_NAV_TAKEOFF

    def typed_items(self, mission_type: int) -> list[Any]:
        """The stored fence (MAV_MISSION_TYPE_FENCE) or rally (MAV_MISSION_TYPE_RALLY) items. Raises ValueError
        for another mission type."""
        if mission_type == M.MAV_MISSION_TYPE_FENCE:
            return self.fence_items
        if mission_type == M.MAV_MISSION_TYPE_RALLY:
            return self.rally_items
        raise ValueError(f"mission_type must be FENCE or RALLY, got {mission_type!r}")

    def set_typed_items(self, mission_type: int, items: list[Any]) -> None:
        """Replace the fence or rally items (see :meth:`typed_items`)."""
        if mission_type == M.MAV_MISSION_TYPE_FENCE:
            self.fence_items = items
        elif mission_type == M.MAV_MISSION_TYPE_RALLY:
            self.rally_items = items
        else:
            raise ValueError(f"mission_type must be FENCE or RALLY, got {mission_type!r}")
