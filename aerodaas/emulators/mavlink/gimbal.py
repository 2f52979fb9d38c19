"""The emulated vehicle's gimbal and camera, as ArduPilot's servo mount and a MAVLink camera present them: the
autopilot is the gimbal manager (MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, MAV_CMD_DO_SET_ROI_LOCATION / _NONE), the
gimbal device reports GIMBAL_DEVICE_ATTITUDE_STATUS (flags ROLL_LOCK | PITCH_LOCK | YAW_IN_VEHICLE_FRAME = 44, as
ArduCopter SITL with ``MNT1_TYPE 1`` sends them) and the manager GIMBAL_MANAGER_INFORMATION (limits in radians);
the camera answers CAMERA_INFORMATION and VIDEO_STREAM_INFORMATION with the stream URI it was given. Angle
conventions: :mod:`aerodaas.navigation.gimbal`."""
from __future__ import annotations

import math
from typing import Any, Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.navigation.gimbal import GimbalLimits, GimbalModel, quaternion_from_euler, roi_angles

M = mavlink

__all__ = ["EmulatedGimbal", "EmulatedCamera"]

#: GIMBAL_DEVICE_FLAGS ROLL_LOCK | PITCH_LOCK | YAW_IN_VEHICLE_FRAME: what ArduCopter's servo mount reports
DEVICE_FLAGS = 4 | 8 | 32
#: GIMBAL_MANAGER_CAP_FLAGS ArduCopter 9070097 reports for a servo mount (observed: 206819)
MANAGER_CAP_FLAGS = 206819


class EmulatedGimbal:
    """A two-axis gimbal on the emulated vehicle. :meth:`command` takes a COMMAND_LONG/INT (params with
    latitude/longitude already in degrees) and returns its MAV_RESULT, or None when the command is not a gimbal
    command; :meth:`step` turns it (and keeps a region of interest in view); :meth:`build` makes its messages."""

    def __init__(self, limits: GimbalLimits | None = None) -> None:
        self.model = GimbalModel(limits or GimbalLimits())
        self.roi_enu: tuple[float, float, float] | None = None

    def command(self, cmd: int, p: list[float], global_to_enu: Callable[[float, float, float], Any]) -> int | None:
        """Carry out a gimbal-manager command. ``global_to_enu(lat, lon, alt_rel_home)`` gives ENU metres."""
        if cmd == M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW:
            pitch = self.model.pitch_deg if math.isnan(p[0]) else p[0]
            yaw = self.model.yaw_deg if math.isnan(p[1]) else p[1]
            lim = self.model.limits
            if not (lim.pitch_min_deg <= pitch <= lim.pitch_max_deg and lim.yaw_min_deg <= yaw <= lim.yaw_max_deg):
                return M.MAV_RESULT_DENIED
            self.roi_enu = None
            self.model.point(pitch, yaw)
            return M.MAV_RESULT_ACCEPTED
        if cmd == M.MAV_CMD_DO_SET_ROI_LOCATION:
            if not all(math.isfinite(v) for v in p[4:7]):
                return M.MAV_RESULT_DENIED
            self.roi_enu = tuple(float(v) for v in global_to_enu(p[4], p[5], p[6]))
            return M.MAV_RESULT_ACCEPTED
        if cmd == M.MAV_CMD_DO_SET_ROI_NONE:
            self.roi_enu = None
            return M.MAV_RESULT_ACCEPTED
        return None

    def step(self, dt: float, position_enu: tuple[float, float, float], yaw_enu_deg: float) -> None:
        """Turn for ``dt`` seconds; with a region of interest, aim at it from the vehicle's pose first."""
        if self.roi_enu is not None:
            self.model.point(*roi_angles(position_enu, yaw_enu_deg, self.roi_enu))
        self.model.step(dt)

    def build(self, msg_id: int, enc: Any, time_boot_ms: int) -> Any | None:
        """GIMBAL_DEVICE_ATTITUDE_STATUS (285) or GIMBAL_MANAGER_INFORMATION (280) from encoder ``enc``; None for
        another id."""
        if msg_id == M.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS:
            q = quaternion_from_euler(0.0, self.model.pitch_deg, self.model.yaw_deg)
            nan = float("nan")
            return enc.gimbal_device_attitude_status_encode(0, 0, time_boot_ms, DEVICE_FLAGS, q, nan, nan, nan, 0,
                                                            nan, nan, 1)
        if msg_id == M.MAVLINK_MSG_ID_GIMBAL_MANAGER_INFORMATION:
            lim = self.model.limits
            return enc.gimbal_manager_information_encode(
                time_boot_ms, MANAGER_CAP_FLAGS, 1, math.radians(-30), math.radians(30),
                math.radians(lim.pitch_min_deg), math.radians(lim.pitch_max_deg),
                math.radians(lim.yaw_min_deg), math.radians(lim.yaw_max_deg))
        return None


class EmulatedCamera:
    """A MAVLink camera (component MAV_COMP_ID_CAMERA) that announces one video stream: ``uri`` (e.g.
    ``rtsp://127.0.0.1:8554/cam``), ``kind`` a VIDEO_STREAM_TYPE, ``resolution`` px, ``framerate_hz``,
    ``hfov_deg``."""

    component = M.MAV_COMP_ID_CAMERA

    def __init__(self, uri: str, kind: int = M.VIDEO_STREAM_TYPE_RTSP, resolution: tuple[int, int] = (1280, 720),
                 framerate_hz: float = 30.0, hfov_deg: int = 80, name: str = "main") -> None:
        self.uri, self.kind, self.resolution = uri, kind, resolution
        self.framerate_hz, self.hfov_deg, self.name = framerate_hz, hfov_deg, name

    def build(self, msg_id: int, enc: Any, time_boot_ms: int) -> Any | None:
        """CAMERA_INFORMATION (259) or VIDEO_STREAM_INFORMATION (269); None for another id."""
        if msg_id == M.MAVLINK_MSG_ID_CAMERA_INFORMATION:
            return enc.camera_information_encode(
                time_boot_ms, b"AeroDaaS".ljust(32, b"\0"), b"emulated camera".ljust(32, b"\0"), 0, 4.5, 6.2, 4.6,
                self.resolution[0], self.resolution[1], 0, M.CAMERA_CAP_FLAGS_HAS_VIDEO_STREAM, 0, b"", 1, 0)
        if msg_id == M.MAVLINK_MSG_ID_VIDEO_STREAM_INFORMATION:
            return enc.video_stream_information_encode(
                1, 1, self.kind, M.VIDEO_STREAM_STATUS_FLAGS_RUNNING, self.framerate_hz, self.resolution[0],
                self.resolution[1], 4000, 0, self.hfov_deg, self.name.encode(), self.uri.encode(),
                M.VIDEO_STREAM_ENCODING_H264, 0)
        return None
