"""The documented physical bounds of a configuration and of the data model (docs/safety.md "Configuration
bounds"): the largest speed, acceleration, altitude, camera size and rate, clock speed-up, duration, seed, battery
energy and power a value may have. Units in the names (m/s, m/s², deg/s, m, px, Hz, s, Wh, W)."""
from __future__ import annotations

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
