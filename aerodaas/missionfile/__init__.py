"""Mission files: QGroundControl ``.plan`` (JSON) and Mission Planner / ArduPilot ``QGC WPL 110`` (text).

Both formats carry MAVLink ``MISSION_ITEM`` rows: a command (``MAV_CMD``), a coordinate frame (``MAV_FRAME``),
``param1``..``param4``, ``x`` = latitude (degrees), ``y`` = longitude (degrees), ``z`` = altitude (metres;
above mean sea level in ``MAV_FRAME_GLOBAL`` 0 / ``MAV_FRAME_GLOBAL_INT`` 5, above home in
``MAV_FRAME_GLOBAL_RELATIVE_ALT`` 3 / ``..._INT`` 6) and an auto-continue flag.

* :func:`load_mission` reads either format (auto-detected from the content), :func:`load_plan` /
  :func:`load_wpl` one of them; :func:`save_plan` / :func:`save_wpl` write them. Loading and saving is
  lossless for every item: ``.plan`` ComplexItems (survey, corridor scan, structure scan, landing patterns)
  are kept verbatim in :attr:`MissionItem.raw` and written back unchanged.
* :func:`plan_to_flight` turns a plan into what an AeroDaaS drone flies: an ordered
  :class:`~aerodaas.model.types.AeroNavigation` of absolute waypoints (latitude, longitude, metres above home), a
  terminal action (land, return to launch, or hover) and the plan's geofence. :func:`plan_to_navigation` is
  the shortcut to the navigation alone; :func:`navigation_to_plan` goes the other way.
* Nothing is dropped silently. Commands the drone cannot honour raise :class:`MissionFileError` naming the
  file, the item (sequence number), the command number and name; commands that only drive a payload may be
  skipped explicitly with ``skip_commands`` (e.g. :data:`PAYLOAD_COMMANDS`) and are then listed in
  :attr:`FlightPlan.skipped`.

Complex items are expanded into MAVLink items the way QGroundControl uploads them:

* ``survey`` and ``CorridorScan`` (``TransectStyleComplexItem``): the ``Items`` array the plan carries, which is
  exactly what QGroundControl sends to the vehicle for a loaded plan (``_loadedMissionItems``), renumbered
  from the complex item's sequence number.
* ``StructureScan`` (version 3): regenerated with QGroundControl's ``StructureScanComplexItem::
  appendMissionItems`` algorithm — the structure polygon is offset outward by ``CameraCalc.DistanceToSurface``
  (``QGCMapPolygon::offset``, Qt ``QLineF`` geometry in a local tangent plane at vertex 0, WGS-84 as current
  QGroundControl's GeographicLib ``LocalCartesian``; older QGroundControl releases used a spherical azimuthal
  projection, which moves the offset vertices by about 0.3 % of the offset distance), then: entrance
  waypoint, ``MAV_CMD_DO_SET_ROI_WPNEXT_OFFSET`` (196), per layer one waypoint per vertex plus the closing
  vertex with ``MAV_CMD_DO_SET_CAM_TRIGG_DIST`` (206) start/stop, ``MAV_CMD_DO_SET_ROI_NONE`` (197) and the
  exit waypoint. A scan whose stored ``Layers`` disagrees with QGroundControl's layer formula, or whose polygon
  cannot be offset, is rejected rather than guessed.
* Other complex items (fixed-wing / VTOL landing patterns, unknown types) are rejected by name when they must
  be expanded (WPL export, flight conversion); ``.plan`` round trips keep them.

Sources: QGroundControl plan file format (``docs/en/qgc-dev-guide/file_formats/plan.md``) and loader/saver
(``MissionController``, ``SimpleMissionItem``, ``MissionItem``, ``GeoFenceController``, ``QGCFencePolygon``,
``QGCFenceCircle``, ``TransectStyleComplexItem``, ``StructureScanComplexItem``, ``QGCMapPolygon``), MAVSDK
``mission_raw/mission_import.cpp``, the MAVLink plain-text mission format (mavlink.io ``file_formats``) and
MAVLink ``common.xml`` (``MAV_CMD``, ``MAV_FRAME``).

Modules, one concept each: :mod:`.commands` (MAVLink ``MAV_CMD`` / ``MAV_FRAME`` numbers and names),
:mod:`._common` (:class:`MissionFileError` and shared helpers), :mod:`.items` (:class:`MissionItem` and the
QGroundControl SimpleItem), :mod:`.plans` (:class:`MissionPlan`, :class:`FlightPlan`), :mod:`.expand`
(ComplexItem expansion), :mod:`.qgc_plan` (``.plan`` JSON), :mod:`.wpl` (``QGC WPL 110``), :mod:`.load`
(format detection) and :mod:`.flight` (plans to and from AeroDaaS navigation). This package re-exports the
public API below.
"""
from aerodaas.missionfile._common import MissionFileError
from aerodaas.missionfile.commands import (
    COMPLEX_ITEM_COMMAND, MAV_CMD_DO_CHANGE_SPEED, MAV_CMD_NAV_LAND, MAV_CMD_NAV_LOITER_TIME, MAV_CMD_NAV_LOITER_UNLIM,
    MAV_CMD_NAV_RETURN_TO_LAUNCH, MAV_CMD_NAV_TAKEOFF, MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL,
    MAV_FRAME_GLOBAL_RELATIVE_ALT, MAV_FRAME_MISSION, PAYLOAD_COMMANDS, command_name, frame_name,
)
from aerodaas.missionfile.expand import expand_items
from aerodaas.missionfile.flight import navigation_to_plan, plan_to_flight, plan_to_navigation
from aerodaas.missionfile.items import MissionItem
from aerodaas.missionfile.load import load_mission
from aerodaas.missionfile.plans import FlightPlan, MissionPlan
from aerodaas.missionfile.qgc_plan import load_plan, save_plan
from aerodaas.missionfile.wpl import load_wpl, save_wpl

__all__ = [
    "MissionFileError", "MissionItem", "MissionPlan", "FlightPlan",
    "load_mission", "load_plan", "load_wpl", "save_plan", "save_wpl",
    "plan_to_flight", "plan_to_navigation", "navigation_to_plan", "expand_items",
    "command_name", "frame_name", "PAYLOAD_COMMANDS", "COMPLEX_ITEM_COMMAND",
    "MAV_CMD_NAV_WAYPOINT", "MAV_CMD_NAV_LOITER_UNLIM", "MAV_CMD_NAV_LOITER_TIME",
    "MAV_CMD_NAV_RETURN_TO_LAUNCH", "MAV_CMD_NAV_LAND", "MAV_CMD_NAV_TAKEOFF", "MAV_CMD_DO_CHANGE_SPEED",
    "MAV_FRAME_GLOBAL", "MAV_FRAME_MISSION", "MAV_FRAME_GLOBAL_RELATIVE_ALT",
]
