"""MAVLink gimbal protocol v2, the ground-station side: point a vehicle's gimbal and follow its reported attitude
(camera discovery, camera protocol v2, is :mod:`aerodaas.backends.mavlink.camera`).

The autopilot is the gimbal manager (ArduPilot 4.3+ for every mount type, PX4's ``gimbal`` module): we send
``MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW`` (1000) or ``MAV_CMD_DO_SET_ROI_LOCATION`` (195) to it and read the gimbal
device's ``GIMBAL_DEVICE_ATTITUDE_STATUS`` (285) and the manager's ``GIMBAL_MANAGER_INFORMATION`` (280, its limits)
(https://mavlink.io/en/services/gimbal_v2.html). Angle conventions: :mod:`aerodaas.navigation.gimbal`.
"""
from __future__ import annotations

import math
import threading
from collections import deque
from dataclasses import dataclass
from typing import Any, Protocol

from aerodaas.backends.mavlink.clock import VehicleClock
from aerodaas.backends.mavlink.command import CommandProtocol
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink.telemetry import VehicleTelemetry
from aerodaas.model.geo import enu_to_geodetic
from aerodaas.navigation.gimbal import GimbalLimits, euler_from_quaternion
from aerodaas.protocol import gimbal as proto

__all__ = ["GimbalAttitude", "GimbalManager", "GimbalConcern", "MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW",
           "MAV_CMD_DO_SET_ROI_LOCATION", "MAV_CMD_DO_SET_ROI_NONE", "MAV_CMD_REQUEST_MESSAGE"]

MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW = 1000
MAV_CMD_DO_SET_ROI_LOCATION = 195
MAV_CMD_DO_SET_ROI_NONE = 197
MAV_CMD_REQUEST_MESSAGE = 512
MAV_FRAME_GLOBAL_RELATIVE_ALT_INT = 6
MSG_CAMERA_INFORMATION, MSG_VIDEO_STREAM_INFORMATION = 259, 269
#: GIMBAL_DEVICE_FLAGS bits (common.xml)
_YAW_IN_VEHICLE_FRAME, _YAW_IN_EARTH_FRAME, _YAW_LOCK = 32, 64, 16
#: VIDEO_STREAM_TYPE: how a camera serves its stream, as the URI scheme AeroDaaS's camera source reads it


class CommandSender(Protocol):
    """Sends one COMMAND_LONG and waits for its acceptance (the MAVLink backend's ``command_long``): ``name`` for
    errors, ``command`` the MAV_CMD number, up to seven float params. Raises the backend's errors on refusal."""

    def __call__(self, name: str, command: int, *params: float) -> None: ...


class CommandIntSender(Protocol):
    """Sends one COMMAND_INT (positions as integers: latitude/longitude degrees x 1e7 in ``x``/``y``, ``z`` metres
    in ``frame``) and waits for its acceptance. Raises the backend's errors on refusal."""

    def __call__(self, name: str, command: int, frame: int, params: tuple[float, float, float, float], x: int,
                 y: int, z: float) -> None: ...


@dataclass(frozen=True)
class GimbalAttitude:
    """A gimbal's attitude as its device reports it: degrees (pitch -90 = nadir; yaw relative to the vehicle's
    nose, positive right, unless ``yaw_in_earth_frame``: then from north, clockwise), ``t_s`` the receiver's time
    of the report in seconds, ``time_boot_ms`` the vehicle's."""

    t_s: float
    time_boot_ms: int
    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    yaw_in_earth_frame: bool
    gimbal_device_id: int

    @classmethod
    def from_status(cls, msg: Any, t_s: float) -> "GimbalAttitude":
        """From a GIMBAL_DEVICE_ATTITUDE_STATUS. The yaw is in the earth frame when the flags say
        YAW_IN_EARTH_FRAME, or (older devices, neither frame flag) YAW_LOCK (common.xml GIMBAL_DEVICE_FLAGS).
        Raises ValueError for a quaternion that is not an attitude (NaN: unknown)."""
        roll, pitch, yaw = euler_from_quaternion(tuple(msg.q))
        flags = int(msg.flags)
        earth = bool(flags & _YAW_IN_EARTH_FRAME) or (not flags & _YAW_IN_VEHICLE_FRAME and bool(flags & _YAW_LOCK))
        return cls(t_s=t_s, time_boot_ms=int(msg.time_boot_ms), roll_deg=roll, pitch_deg=pitch, yaw_deg=yaw,
                   yaw_in_earth_frame=earth, gimbal_device_id=int(getattr(msg, "gimbal_device_id", 0)))


class GimbalManager:
    """Points a vehicle's gimbal within ``limits`` (checked here, before anything is sent) and keeps its latest
    attitude and the limits the vehicle itself reports. One object per vehicle; :meth:`on_message` is fed every
    message from the vehicle (any thread), :meth:`point` / :meth:`point_at` are called from the control thread."""

    def __init__(self, send: CommandSender, send_int: CommandIntSender, limits: GimbalLimits | None = None,
                 gimbal_device_id: int = 0) -> None:
        self._send, self._send_int = send, send_int
        self.limits = limits or GimbalLimits()
        self.gimbal_device_id = gimbal_device_id
        self._lock = threading.Lock()
        self._attitude: GimbalAttitude | None = None
        self._vehicle_limits: GimbalLimits | None = None

    def point(self, pitch_deg: float, yaw_deg: float) -> None:
        """Aim the gimbal at ``pitch_deg`` (up positive, -90 nadir) and ``yaw_deg`` (relative to the vehicle's nose,
        positive right), degrees, with MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW (rates NaN: the gimbal's own; flags 0:
        yaw follows the vehicle). Raises ValueError (naming the axis and value) outside :attr:`limits` or the
        vehicle's own reported limits, and the sender's errors when the autopilot refuses."""
        self.limits.check(pitch_deg, yaw_deg)
        if self._vehicle_limits is not None:
            self._vehicle_limits.check(pitch_deg, yaw_deg)
        nan = float("nan")
        self._send("DO_GIMBAL_MANAGER_PITCHYAW", MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, float(pitch_deg),
                   float(yaw_deg), nan, nan, 0.0, 0.0, float(self.gimbal_device_id))

    def point_at(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Let the autopilot keep the gimbal on a region of interest: MAV_CMD_DO_SET_ROI_LOCATION as a COMMAND_INT
        in MAV_FRAME_GLOBAL_RELATIVE_ALT_INT (latitude and longitude in degrees, ``alt_m`` metres above home).
        COMMAND_INT, as the MAVLink command protocol asks for commands that carry a position: a COMMAND_LONG's
        float32 longitude resolves only about 1 m at 100 degrees. The autopilot points from its own position (its
        GLOBAL_POSITION_INT reads 0 N 0 E until its EKF has an origin). Raises ValueError for a non-finite or
        impossible position."""
        if not (math.isfinite(lat_deg) and math.isfinite(lon_deg) and math.isfinite(alt_m)) \
                or not -90.0 <= lat_deg <= 90.0 or not -180.0 <= lon_deg <= 180.0:
            raise ValueError(f"gimbal region of interest lat {lat_deg!r}, lon {lon_deg!r}, alt {alt_m!r} is not a "
                             f"position")
        self._send_int("DO_SET_ROI_LOCATION", MAV_CMD_DO_SET_ROI_LOCATION, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                       (float(self.gimbal_device_id), 0.0, 0.0, 0.0), int(round(lat_deg * 1e7)),
                       int(round(lon_deg * 1e7)), float(alt_m))

    def release(self) -> None:
        """Stop pointing at a region of interest (MAV_CMD_DO_SET_ROI_NONE)."""
        self._send("DO_SET_ROI_NONE", MAV_CMD_DO_SET_ROI_NONE, float(self.gimbal_device_id))

    def on_message(self, msg: Any, t_s: float) -> GimbalAttitude | None:
        """Take a message from the vehicle; returns the new attitude for a GIMBAL_DEVICE_ATTITUDE_STATUS with a
        known attitude (None otherwise). GIMBAL_MANAGER_INFORMATION updates the vehicle's limits (radians on the
        wire)."""
        kind = msg.get_type()
        if kind == "GIMBAL_DEVICE_ATTITUDE_STATUS":
            try:
                att = GimbalAttitude.from_status(msg, t_s)
            except ValueError:
                return None
            with self._lock:
                self._attitude = att
            return att
        if kind == "GIMBAL_MANAGER_INFORMATION":
            try:
                lim = GimbalLimits(pitch_min_deg=math.degrees(msg.pitch_min), pitch_max_deg=math.degrees(msg.pitch_max),
                                   yaw_min_deg=max(-180.0, math.degrees(msg.yaw_min)),
                                   yaw_max_deg=min(180.0, math.degrees(msg.yaw_max)), rate_deg_s=self.limits.rate_deg_s)
            except ValueError:
                return None  # a manager reporting no usable limits: ours stand alone
            with self._lock:
                self._vehicle_limits = lim
        return None

    @property
    def attitude(self) -> GimbalAttitude | None:
        """The latest reported attitude (None before the first)."""
        with self._lock:
            return self._attitude

    @property
    def vehicle_limits(self) -> GimbalLimits | None:
        """The limits the vehicle's gimbal manager reported (None before its GIMBAL_MANAGER_INFORMATION)."""
        with self._lock:
            return self._vehicle_limits


class GimbalConcern:
    """The MAVLink backend's gimbal (``backend.gimbal``): carries out the drone's gimbal commands
    (:data:`aerodaas.protocol.gimbal.GimbalCommand`) through a :class:`GimbalManager` speaking with the backend's
    ``command_long`` / ``command_int``, converts a region of interest from ENU metres to the vehicle's home-relative
    latitude/longitude/altitude, and keeps the GIMBAL_DEVICE_ATTITUDE_STATUS reports (up to 600, oldest dropped) for
    the drone to record. ``limits``: the robot's ``gimbal`` section (None: no gimbal configured); its
    collaborators: ``commands`` (the command protocol: ``command_long``, ``command_int``), ``telemetry`` (the ENU
    origin ``home``), ``clock`` (vehicle seconds of each report) and ``link`` (it registers its message handlers
    and, with a gimbal configured, asks for GIMBAL_DEVICE_ATTITUDE_STATUS with the telemetry streams)."""

    #: GIMBAL_DEVICE_ATTITUDE_STATUS's rate asked of the vehicle (SET_MESSAGE_INTERVAL), Hz
    STATUS_HZ = 10.0

    def __init__(self, limits: GimbalLimits | None, *, commands: CommandProtocol, telemetry: VehicleTelemetry,
                 clock: VehicleClock, link: MavlinkLink) -> None:
        self._telemetry, self._clock = telemetry, clock
        self.configured = limits is not None
        self.manager = GimbalManager(commands.command_long, commands.command_int, limits)
        self._reports: deque[proto.GimbalAttitude] = deque(maxlen=600)
        self._latest: proto.GimbalAttitude | None = None
        self._lock = threading.Lock()
        link.handle("GIMBAL_DEVICE_ATTITUDE_STATUS", self.on_message)
        link.handle("GIMBAL_MANAGER_INFORMATION", self.on_message)
        link.add_streams(self)

    def streams(self) -> tuple:
        """(message id, Hz) to request of the vehicle: GIMBAL_DEVICE_ATTITUDE_STATUS when a gimbal is configured."""
        return ((285, self.STATUS_HZ),) if self.configured else ()

    def point(self, cmd: proto.GimbalCommand) -> None:
        """Send ``cmd`` (pitch/yaw: DO_GIMBAL_MANAGER_PITCHYAW; ROI: DO_SET_ROI_LOCATION at the ENU point's
        latitude/longitude and ``z`` metres above home; release: DO_SET_ROI_NONE). Raises the backend's
        CommandRefused / LinkLost / BackendError, ValueError for values outside the limits."""
        if isinstance(cmd, proto.GimbalPoint):
            self.manager.point(cmd.pitch_deg, cmd.yaw_deg)
        elif isinstance(cmd, proto.GimbalRoi):
            g = enu_to_geodetic(cmd.x, cmd.y, cmd.z, self._telemetry.home)
            self.manager.point_at(g.lat, g.lon, cmd.z)
        elif isinstance(cmd, proto.GimbalRelease):
            self.manager.release()
        else:
            raise TypeError(f"not a gimbal command: {cmd!r}")

    def on_message(self, msg: Any) -> None:
        """A GIMBAL_DEVICE_ATTITUDE_STATUS or GIMBAL_MANAGER_INFORMATION from the vehicle (the I/O thread)."""
        att = self.manager.on_message(msg, float(self._clock.t))
        if att is None:
            return
        q = tuple(float(v) for v in msg.q)
        n = math.sqrt(sum(v * v for v in q)) or 1.0
        rec = proto.GimbalAttitude(t=att.t_s, q=tuple(v / n for v in q), roll_deg=att.roll_deg,
                                   pitch_deg=att.pitch_deg, yaw_deg=att.yaw_deg,
                                   yaw_in_earth_frame=att.yaw_in_earth_frame, source="mavlink")
        with self._lock:
            self._reports.append(rec)
            self._latest = rec

    def latest(self) -> proto.GimbalAttitude | None:
        """The latest reported attitude (None before the first)."""
        with self._lock:
            return self._latest

    def drain(self) -> list[proto.GimbalAttitude]:
        """Every report not handed out yet, oldest first."""
        with self._lock:
            out = list(self._reports)
            self._reports.clear()
        return out
