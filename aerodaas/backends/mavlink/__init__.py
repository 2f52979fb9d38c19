"""MAVLink autopilots (ArduPilot Copter, PX4 multicopter) as a vehicle backend, through pymavlink.

One background I/O thread reads every message (pymavlink parses; unknown ids, bad CRCs and duplicates from
several captured links are skipped, never raised), keeps the state, sends our GCS HEARTBEAT at 1 Hz, re-sends the
active position/velocity target at ``setpoint_rate_hz`` in the *vehicle's* time (so an emulator running K times
faster than real time still sees PX4's required > 2 Hz offboard stream) and watches the autopilot's HEARTBEAT for
link loss. The control thread sends commands and waits for their acknowledgements.

Protocols (mavlink.io): heartbeat/connection, command protocol (COMMAND_LONG -> COMMAND_ACK with retries and the
``confirmation`` counter), message intervals (MAV_CMD_SET_MESSAGE_INTERVAL, else the deprecated
REQUEST_DATA_STREAM), offboard control (SET_POSITION_TARGET_GLOBAL_INT / _LOCAL_NED with
POSITION_TARGET_TYPEMASK), the mission protocol (MISSION_COUNT / MISSION_REQUEST_INT / MISSION_ITEM_INT /
MISSION_ACK, both directions). Mode numbers are pymavlink's tables (``mavutil.mode_mapping_byname`` for
ArduPilot, ``mavutil.px4_map`` for PX4 main/sub modes).

Flavour differences handled here: ArduPilot flies targets in GUIDED, PX4 in OFFBOARD (entered only after the
setpoint stream runs); MAV_CMD_NAV_TAKEOFF ``param7`` is metres above home on ArduPilot and metres above mean sea
level on PX4; ArduPilot missions carry home at sequence 0.

One module per MAVLink concern, the way MAVSDK splits its plugins, and composed as MAVSDK composes a ``System``:
each concern declares its state in its ``__init__`` and is given its collaborators there as typed objects (the
link, the clock, the telemetry store, the command protocol...; small Protocols where a module cycle would
otherwise form), never the backend; those made on the link register what they receive with it
(:mod:`.routes`: ``link.serve_commands``, ``link.handle``...), and every concern records its events in
``backend.events`` (:class:`~.events.EventLog`). The concerns: ``backend.commands`` (:class:`~.command.CommandProtocol`: the command protocol, mode
changes confirmed by the HEARTBEAT), ``backend.parameters`` (:class:`~.params.ParameterProtocol`: the parameter protocol),
``backend.speed_limits`` (:class:`~.params.SpeedLimits`: the vehicle's own speed limits, lowered in flight for
the estimator's margin),
``backend.transfers`` (:class:`~.transfer.MissionTransfer`: every mission-protocol exchange, mission, fence and
rally items), ``backend.mission`` (:class:`~.mission.AutopilotMission`: the mission built from waypoints, its
upload, download and start, and its progress), ``backend.actions`` (:class:`~.action.VehicleAction`: readiness,
arming, disarming, take-off: the contract's command group ``actions``), ``backend.guidance``
(:class:`~.offboard.OffboardControl`: GUIDED/OFFBOARD targets, hold/land/RTL, safe end: the command group
``guidance``), ``backend.signed_only`` (:class:`~.signing.SignedOnly`: ``mavlink.require_signing`` for what moves
the vehicle), ``backend.fence`` (:class:`~.fence.AutopilotFence`: the autopilot's own geofence and rally points,
FENCE_* / GF_* parameters, read back before flight),
``backend.telemetry`` (:class:`~.telemetry.VehicleTelemetry`: the state the streams report, the ENU origin
``home`` and the position samples the runtime records, the contract's ``telemetry``; its message handlers in an
explicit table), ``backend.link`` (:class:`~.link.MavlinkLink`: connection, autopilot HEARTBEAT, I/O thread,
dispatch, stream requests), ``backend.clock`` (:class:`~.clock.VehicleClock`: the vehicle clock from
``time_boot_ms``), ``backend.status_texts`` (:class:`~.statustext.StatusTexts`), ``backend.cameras`` (:class:`~.camera.CameraFinder`)
and ``backend.gimbal`` (:class:`~.gimbal.GimbalConcern`, the contract's ``gimbal``). No concern is a mix-in, and
none has a second name on the backend: :class:`MavlinkBackend` holds them, reads its
:class:`~aerodaas.backends.base.VehicleState` from the telemetry, link and clock, and connects and closes. Verified against real ArduCopter and PX4 SITL firmware (``tests/firmware/test_sitl_*.py``).
"""
from aerodaas.backends.mavlink.backend import MavlinkBackend
from aerodaas.backends.mavlink._common import CommandNotAcknowledged, CommandNotConfirmed

__all__ = ["MavlinkBackend", "CommandNotAcknowledged", "CommandNotConfirmed"]
