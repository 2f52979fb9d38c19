"""The configuration's foundations: :class:`ConfigError`, the strict base of every section (unknown keys refused,
finite numbers, strict types), the documented physical bounds and the "did you mean" helper."""
from __future__ import annotations


from pydantic import BaseModel, ConfigDict


DATA_DIR_ENV = "AERODAAS_DATA_DIR"


class ConfigError(ValueError):
    """A malformed environment file; the message names each bad field and its value."""


class _Cfg(BaseModel):
    """Every configuration section: unknown keys are refused (with a "did you mean" suggestion, see
    :func:`_format_errors`), numbers must be finite (no NaN/Infinity), and types are strict: ``"yes"`` or ``1``
    is not a boolean, ``"3"`` is not a number (JSON has real booleans and numbers)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


#: Documented physical bounds of the configuration (docs/safety.md "Configuration bounds"). Numbers outside them are
#: refused: they are typos or attacks, not vehicles (a 1e308 m/s speed limit disables the check it configures).
MAX_SPEED_MPS = 100.0  # fastest multirotors are ~ 60 m/s
MAX_ACCEL_MPS2 = 100.0
MAX_YAW_RATE_DPS = 3600.0
MAX_ALTITUDE_M = 10_000.0  # above home
#: horizontal distance from home (metres) of any waypoint or velocity command: the default of
#: ``safety.max_distance`` (its upper bound is ``aerodaas.model.types.MAX_LOCAL_M``, 100 km)
DEFAULT_MAX_DISTANCE_M = 10_000.0
HOME_ALT_RANGE_M = (-500.0, 9_000.0)  # AMSL: below the Dead Sea shore .. above Everest
MAX_CAMERA_PX = 8192  # per side
MAX_CAMERA_FPS = 240.0
MAX_RATE_HZ = 1000.0  # control, physics, odometry, stream rates
MAX_SPEEDUP = 1000.0
#: slowest simulation clock: 100x slower than real time (below, one simulated second takes minutes of wall time and a
#: run looks hung; 1e-300 overflowed the clock's arithmetic)
MIN_SPEEDUP = 0.01
#: coarsest physics step: 1/10 s, the control period the safety gate's envelope model assumes (aerodaas.navigation.safety);
#: measured with aerodaas.reliability.flight: no fence/altitude excursion at 10, 20, 50 Hz, 0.77 m outside the fence
#: at 1 Hz
MIN_PHYSICS_HZ = 10.0
#: largest procedural ground, pixels per side (size_m / metres_per_pixel): 16384² RGB is 805 MB
MAX_GROUND_PX = 16384
#: random seeds: numpy's legacy generators take 0 .. 2**32 - 1
MAX_SEED = 2**32 - 1
#: slowest control loop (Hz): the drone's tick checks the battery failsafes, the geofence and the queue; at 1e-6 Hz
#: it sat in take-off until the battery read 0 %, no failsafe fired and the run ended armed
MIN_CONTROL_HZ = 1.0
#: largest image file (ground texture, target crops), pixels per side, read from the file's header before decoding:
#: a PNG "decompression bomb" (a few KB that decode to gigabytes) raised cv2.error; as MAX_GROUND_PX
MAX_IMAGE_SIDE_PX = 16384
#: most items of one list in environment.json (robots, compute resources, sensors, world targets): far above any
#: fleet (the fleet benchmark flies 40), and a bound on the work validation does
MAX_LIST_ITEMS = 1000
MAX_DURATION_S = 86_400.0  # timeouts and intervals: one day
MAX_BATTERY_WH = 100_000.0
MAX_POWER_W = 1_000_000.0


def did_you_mean(word: str, choices) -> str:
    """``" (did you mean 'width'?)"`` for the closest of ``choices`` to a misspelt ``word`` (difflib), else ``""``."""
    import difflib

    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""
