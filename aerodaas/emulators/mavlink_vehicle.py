"""Compatibility path: the MAVLink vehicle emulator now lives in the :mod:`aerodaas.emulators.mavlink` package
(one module per concern)."""
from aerodaas.emulators.mavlink import ARDUCOPTER_MODES, PX4_MODES, MavlinkVehicleEmulator, parse_endpoint

__all__ = ["MavlinkVehicleEmulator", "ARDUCOPTER_MODES", "PX4_MODES", "parse_endpoint"]
