"""The embedded flight model exposed as a MAVLink vehicle that behaves like ArduCopter or PX4 (multicopter), one
object per MAVLink concern, each in its module and given the collaborators it uses: :mod:`.state` (the vehicle's
state, clock, settings and readiness; the stored mission items), :mod:`.link` (sockets, parsing, STATUSTEXT),
:mod:`.telemetry` (streams and messages), :mod:`.motion` (position control, take-off, landing, speeds),
:mod:`.arming` (readiness reports, home, arming), :mod:`.modes` (flight modes, take-off command, RTL),
:mod:`.guided` (GUIDED / OFFBOARD targets), :mod:`.mission` (mission transfer), :mod:`.mission_run` (flying the
mission: hold and MISSION_ITEM_REACHED), :mod:`.commands` (command protocol), :mod:`.params` (parameter protocol),
:mod:`.autopilot` (the per-step logic: auto-disarm, failsafes, take-off completion), :mod:`.gimbal`,
:mod:`.camera`, :mod:`.signing`; :mod:`.vehicle` composes them. :mod:`.flavour` holds what was read from the
firmware (parameter defaults and units, sensor bits, EKF flags), :mod:`.constants` the MAVLink tables;
:mod:`.trace` is the scripted ground-station sequence that compares a vehicle (ours or real firmware) with another."""
from aerodaas.emulators.mavlink.constants import ARDUCOPTER_MODES, PX4_MODES
from aerodaas.emulators.mavlink.link import parse_endpoint
from aerodaas.emulators.mavlink.vehicle import MavlinkVehicleEmulator

__all__ = ["MavlinkVehicleEmulator", "ARDUCOPTER_MODES", "PX4_MODES", "parse_endpoint"]
