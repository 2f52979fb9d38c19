"""``environment.json``: the configuration of robots, sensors, compute resources and the simulated world.

Everything is validated with pydantic before any actor starts. :func:`load_environment_config` turns any
validation problem into :class:`ConfigError`, whose message names the JSON path of the field and the bad
value, e.g. ``robots.0.limits.max_speed: Input should be greater than 0 (got -1)``.
Relative file paths (imagery) are resolved against the environment file's folder, then
``$AERODAAS_DATA_DIR``; ``package:NAME`` names an image shipped in the package (``aerodaas/sim/ground``).
"""
from __future__ import annotations

from aerodaas.config.base import ConfigError, DATA_DIR_ENV, did_you_mean, _Cfg  # noqa: F401
from aerodaas.model.bounds import (HOME_ALT_RANGE_M, MAX_ACCEL_MPS2, MAX_ALTITUDE_M, MAX_BATTERY_WH, MAX_CAMERA_FPS,
                                   MAX_CAMERA_PX, MAX_DURATION_S, MAX_POWER_W, MAX_RATE_HZ, MAX_SPEEDUP, MAX_SPEED_MPS,
                                   MAX_YAW_RATE_DPS, MIN_PHYSICS_HZ, MIN_SPEEDUP, MAX_GROUND_PX, MAX_SEED)  # noqa: F401
from aerodaas.config.robot import (BatteryConfig, Limits, NoiseConfig, ProgressConfig, RobotConfig, SafetyConfig,
                                   SensorConfig)  # noqa: F401
from aerodaas.config.backends import MavlinkConfig, MavlinkFenceConfig, ReplayConfig, TelloConfig  # noqa: F401
from aerodaas.config.environment import (AnalyticsQosConfig, AnalyticsSchedulerConfig, ComputeConfig, EnvironmentConfig,
                          GroundConfig, HitlConfig, SimulationConfig, TargetConfig, TargetPathPoint, WorldConfig,
                          json_schema, load_environment_config, parse_environment_config, _format_errors)  # noqa: F401
