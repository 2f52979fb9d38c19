"""A robot's phase deadlines (``robots[].deadlines`` of ``environment.json``): how long take-off, landing and the
return to launch may take, in vehicle seconds, and what the drone does when one is overrun.
The formula is :mod:`aerodaas.navigation.deadlines`; the drone applies it in :mod:`aerodaas.actors.drone.deadline`."""
from __future__ import annotations

from typing import Literal

from pydantic import Field

from aerodaas.config.base import _Cfg
from aerodaas.model.bounds import MAX_ALTITUDE_M, MAX_DURATION_S, MAX_SPEED_MPS

__all__ = ["PhaseDeadlinesConfig"]


class PhaseDeadlinesConfig(_Cfg):
    """Every flight phase is bounded. A phase's deadline (vehicle seconds, counted from the control step that first
    sees the phase; each entry into it starts a new one) is ``speed_factor`` x (distance / speed of each of its
    legs) + ``margin_s``: take-off climbs ``takeoff_altitude`` at ``limits.max_vertical_speed``; landing descends
    from its height at ``landing_speed`` (never above ``limits.max_vertical_speed``); a return to launch flies its
    path at the robot's horizontal speed limit, and, when the autopilot flies it, also climbs to
    ``autopilot_return_alt`` and lands (the autopilot's RTL ends on the ground). ``takeoff_s``, ``landing_s`` and
    ``rtl_s`` replace the derived deadline of their phase with a fixed one.

    Past its deadline the phase is stalled: a ``takeoff_stalled`` / ``landing_stalled`` / ``rtl_stalled`` event
    (with the deadline, its legs, the vehicle's height and distance from home), the mission's outcome becomes the
    event's name unless an earlier cause already ended it as not successful, and the phase's action:
    ``on_takeoff_stalled`` ``land`` (default: come down and disarm where it is), ``hold`` (PAUSED: hover or stay
    until an operator resumes, which commands the take-off again) or ``abort`` (the mission ends now; a real
    vehicle gets the backend's safe end, e.g. ``mavlink.on_close``); ``on_rtl_stalled`` the same three (default
    ``land``: land where it is); ``on_landing_stalled`` ``land`` (default: command the landing once more, with a
    new deadline; a second overrun aborts) or ``abort``. A backend that declares ``needs_takeoff = False`` (a
    ground vehicle) has no take-off phase."""

    speed_factor: float = Field(default=2.0, ge=1.0, le=100.0, description="multiplies the nominal time of a phase "
                                "(its legs at the vehicle's limits): a vehicle may fly below its limit")
    margin_s: float = Field(default=15.0, ge=0, le=MAX_DURATION_S, description="vehicle seconds added to every "
                            "derived deadline: spool-up after arming, a land detector confirming touchdown")
    landing_speed: float = Field(default=0.5, gt=0, le=MAX_SPEED_MPS, description="m/s the landing is judged by "
                                 "(ArduCopter LAND_SPEED 50 cm/s, PX4 MPC_LAND_SPEED 0.7 m/s, the simulator 0.5)")
    autopilot_return_alt: float = Field(default=60.0, ge=0, le=MAX_ALTITUDE_M, description="metres above home an "
                                        "autopilot's own RTL may climb to before it returns (ArduCopter RTL_ALT 15 m, "
                                        "PX4 RTL_RETURN_ALT up to 60 m)")
    takeoff_s: float | None = Field(default=None, gt=0, le=MAX_DURATION_S, description="fixed take-off deadline, "
                                    "vehicle seconds (absent: derived)")
    landing_s: float | None = Field(default=None, gt=0, le=MAX_DURATION_S, description="fixed landing deadline, "
                                    "vehicle seconds (absent: derived)")
    rtl_s: float | None = Field(default=None, gt=0, le=MAX_DURATION_S, description="fixed return-to-launch "
                                "deadline, vehicle seconds (absent: derived)")
    on_takeoff_stalled: Literal["land", "hold", "abort"] = "land"
    on_landing_stalled: Literal["land", "abort"] = "land"
    on_rtl_stalled: Literal["land", "hold", "abort"] = "land"
