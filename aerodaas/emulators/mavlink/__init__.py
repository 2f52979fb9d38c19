"""The embedded flight model exposed as a MAVLink vehicle that behaves like ArduCopter or PX4 (multicopter), one
module per MAVLink concern: :mod:`.link` (sockets, parsing, STATUSTEXT), :mod:`.commands` (command protocol),
:mod:`.modes` (flight modes, RTL, take-off, auto-disarm), :mod:`.arming` (readiness: EKF / health, pre-arm
checks, arming), :mod:`.guided` (GUIDED / OFFBOARD targets), :mod:`.params` (parameter protocol and the
firmware's defaults), :mod:`.mission` (mission transfer), :mod:`.mission_run` (flying the mission: hold and
MISSION_ITEM_REACHED), :mod:`.telemetry` (streams and messages), :mod:`.flavour` (what was read from the firmware:
parameter defaults and units, sensor bits, EKF flags), :mod:`.constants`; :mod:`.trace` is the scripted
ground-station sequence that compares a vehicle (ours or real firmware) with another."""
from aerodaas.emulators.mavlink.constants import ARDUCOPTER_MODES, PX4_MODES
from aerodaas.emulators.mavlink.link import parse_endpoint
from aerodaas.emulators.mavlink.vehicle import MavlinkVehicleEmulator

__all__ = ["MavlinkVehicleEmulator", "ARDUCOPTER_MODES", "PX4_MODES", "parse_endpoint"]
