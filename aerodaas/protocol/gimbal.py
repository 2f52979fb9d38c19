"""Gimbal commands and attitude as the application, the drone actor and the vehicle backends exchange them.

A command is one of three frozen dataclasses (:data:`GimbalCommand`): :class:`GimbalPoint` (pitch and yaw in
degrees, gimbal protocol v2's conventions: pitch 0 at the horizon, -90 straight down; yaw relative to the vehicle's
nose, positive right), :class:`GimbalRoi` (a region of interest in ENU metres from home, which the gimbal keeps in
view) and :class:`GimbalRelease` (stop following the region of interest). :class:`GimbalAttitude` is what a backend
reports of its gimbal (the simulator's model, or a MAVLink vehicle's ``GIMBAL_DEVICE_ATTITUDE_STATUS``) and what is
recorded on ``/<robot>/gimbal``. Conventions: :mod:`aerodaas.navigation.gimbal`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Union

__all__ = ["GimbalPoint", "GimbalRoi", "GimbalRelease", "GimbalCommand", "GimbalAttitude"]


@dataclass(frozen=True)
class GimbalPoint:
    """Point the gimbal at ``pitch_deg`` (up positive, -90 nadir) and ``yaw_deg`` (relative to the vehicle's nose,
    positive right), degrees (MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW)."""

    pitch_deg: float
    yaw_deg: float

    def describe(self) -> dict:
        """The command for the recording's events (JSON)."""
        return {"command": "point", "pitch_deg": self.pitch_deg, "yaw_deg": self.yaw_deg}


@dataclass(frozen=True)
class GimbalRoi:
    """Keep the camera on the point (``x``, ``y``, ``z``) ENU metres from home (MAV_CMD_DO_SET_ROI_LOCATION)."""

    x: float
    y: float
    z: float

    def describe(self) -> dict:
        """The command for the recording's events (JSON)."""
        return {"command": "roi", "roi_enu": [self.x, self.y, self.z]}


@dataclass(frozen=True)
class GimbalRelease:
    """Stop following a region of interest (MAV_CMD_DO_SET_ROI_NONE); the gimbal stays where it points."""

    def describe(self) -> dict:
        """The command for the recording's events (JSON)."""
        return {"command": "release"}


#: one gimbal command
GimbalCommand = Union[GimbalPoint, GimbalRoi, GimbalRelease]


@dataclass(frozen=True)
class GimbalAttitude:
    """A gimbal's attitude at vehicle time ``t`` (s): ``q`` (w, x, y, z) the rotation of the camera relative to the
    vehicle (yaw relative to the nose) or to north when ``yaw_in_earth_frame`` (FRD, ZYX as
    GIMBAL_DEVICE_ATTITUDE_STATUS), and its Euler angles in degrees. ``source``: ``sim`` (the simulator's gimbal
    model) or ``mavlink`` (the vehicle's report)."""

    t: float
    q: tuple[float, float, float, float]
    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    yaw_in_earth_frame: bool = False
    source: str = "sim"

    def record(self, robot: str) -> dict:
        """The ``aerodaas.GimbalAttitude`` message of robot ``robot`` (JSON)."""
        return {"robot": robot, "t": self.t, "q": list(self.q), "roll_deg": self.roll_deg,
                "pitch_deg": self.pitch_deg, "yaw_deg": self.yaw_deg, "yaw_in_earth_frame": self.yaw_in_earth_frame,
                "source": self.source}
