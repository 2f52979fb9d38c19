"""Mission plans: :class:`MissionPlan` (a mission as the files hold it: home, items, geofence, rally points) and
:class:`FlightPlan` (what an AeroDaaS drone flies for it: ordered absolute waypoints, terminal action, geofence)."""
from __future__ import annotations

from typing import Literal

from pydantic import Field

from aerodaas.navigation.geofence import GeofenceConfig
from aerodaas.model.types import AeroNavigation, GeoPoint
from aerodaas.missionfile.expand import expand_items
from aerodaas.missionfile.items import MissionItem, _Model


class MissionPlan(_Model):
    """A mission as the files hold it.

    * ``home``: planned home position (``plannedHomePosition`` / WPL row 0), latitude/longitude in degrees and
      altitude in metres above mean sea level; ``None`` when the file has none.
    * ``items``: mission items in order (see :class:`MissionItem`).
    * ``geofence``: inclusion/exclusion polygons and circles (``geoFence``).
    * ``cruise_speed`` / ``hover_speed``: QGroundControl's planning speeds in m/s (fixed-wing / multirotor).
      They are planning defaults for time estimates, not uploaded to the vehicle, so :func:`plan_to_flight`
      does not apply them (a ``MAV_CMD_DO_CHANGE_SPEED`` item does).
    * ``firmware_type`` (``MAV_AUTOPILOT``, 12 = PX4, 3 = ArduPilot) / ``vehicle_type`` (``MAV_TYPE``, 2 =
      quadrotor): as stored in a ``.plan``. QGroundControl requires ``firmwareType``, so ``None`` writes 12
      (PX4); ``vehicleType`` is optional and omitted when ``None``.
    * ``rally_points``: ``(latitude, longitude, altitude above home m)`` safe points (``rallyPoints``).
    * ``breach_return``: fence breach return point ``(latitude, longitude, altitude m)`` (``geoFence.breachReturn``).
    * ``source``: the file the plan was read from (used in error messages; not part of the mission).
    """

    home: GeoPoint | None = None
    items: list[MissionItem] = Field(default_factory=list)
    geofence: GeofenceConfig = Field(default_factory=GeofenceConfig)
    cruise_speed: float | None = Field(default=None, ge=0.0)
    hover_speed: float | None = Field(default=None, ge=0.0)
    firmware_type: int | None = None
    vehicle_type: int | None = None
    rally_points: list[tuple[float, float, float]] = Field(default_factory=list)
    breach_return: tuple[float, float, float] | None = None
    source: str | None = None

    def expanded_items(self) -> list[MissionItem]:
        """The MAVLink items a vehicle would receive: ComplexItems expanded (see :mod:`aerodaas.missionfile`), simple
        items as they are. Raises :class:`MissionFileError` naming any ComplexItem that cannot be expanded
        faithfully."""
        return expand_items(self)

    def same_mission(self, other: "MissionPlan") -> bool:
        """True when both plans describe the same mission (everything except ``source``)."""
        return self.model_dump(exclude={"source"}) == other.model_dump(exclude={"source"})


class FlightPlan(_Model):
    """What an AeroDaaS drone flies for a mission plan.

    * ``navigation``: ORDERED, DISTANCE_DRIVEN absolute waypoints (``x`` latitude, ``y`` longitude in degrees,
      ``z`` metres above home) with ids ``"item<seq>"``.
    * ``final_action``: what follows the last waypoint: ``"land"`` (``MAV_CMD_NAV_LAND`` 21), ``"rtl"``
      (``MAV_CMD_NAV_RETURN_TO_LAUNCH`` 20) or ``"hover"`` (no terminal command, or a final
      ``MAV_CMD_NAV_LOITER_UNLIM`` 17: hold position at the last waypoint, as PX4 and ArduPilot do).
    * ``geofence``: the plan's fence; ``home``: the home used for altitudes (``None`` if unknown).
    * ``skipped``: one line per item skipped through ``skip_commands``.
    """

    navigation: AeroNavigation
    final_action: Literal["land", "rtl", "hover"] = "hover"
    geofence: GeofenceConfig = Field(default_factory=GeofenceConfig)
    home: GeoPoint | None = None
    skipped: list[str] = Field(default_factory=list)
