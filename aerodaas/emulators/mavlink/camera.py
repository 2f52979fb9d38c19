"""A MAVLink camera component on the emulated vehicle's system (camera protocol v2), as a companion computer's
camera manager (mavlink-camera-manager, MAVSDK's camera server) presents one: its own HEARTBEAT (MAV_TYPE_CAMERA,
MAV_AUTOPILOT_INVALID) at 1 Hz of vehicle time from its own component id, and answers to the requests addressed to
it: MAV_CMD_REQUEST_MESSAGE for CAMERA_INFORMATION / VIDEO_STREAM_INFORMATION, and the older
MAV_CMD_REQUEST_CAMERA_INFORMATION / MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION (a COMMAND_ACK, then the message).
The messages themselves are :class:`~aerodaas.emulators.mavlink.gimbal.EmulatedCamera`'s. Each link gets an
encoder of the camera's own (its own sequence numbers, as a separate component has)."""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.gimbal import EmulatedCamera
    from aerodaas.emulators.mavlink.link import _Link

M = mavlink

#: what each request asks the camera for
_ASKS = {M.MAV_CMD_REQUEST_CAMERA_INFORMATION: M.MAVLINK_MSG_ID_CAMERA_INFORMATION,
         M.MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION: M.MAVLINK_MSG_ID_VIDEO_STREAM_INFORMATION}


class CameraHostMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator`: :meth:`attach_camera` puts a camera
    component on the vehicle's system (none by default)."""

    camera: "EmulatedCamera | None" = None

    def attach_camera(self, camera: "EmulatedCamera | None") -> None:
        """Put ``camera`` on the vehicle's system (None takes it away): its HEARTBEAT starts with the next one
        of the autopilot, and it answers requests addressed to its component id."""
        with self._lock:
            self.camera = camera
            self._camera_mavs: dict[int, Any] = {}
            #: (command, component asked) of every request the camera answered
            self.camera_requests: list[tuple[int, int]] = []

    def _camera_send(self, msg: Any, link: "_Link | None" = None) -> None:
        """Send ``msg`` from the camera's component on ``link`` (None: every link)."""
        for lk in [link] if link is not None else list(self._links):
            mav = self._camera_mavs.get(id(lk))
            if mav is None:
                mav = self._camera_mavs[id(lk)] = M.MAVLink(lk, srcSystem=self.system_id,
                                                            srcComponent=self.camera.component)
            try:
                mav.send(msg)
            except Exception:  # noqa: BLE001 - a closed link: the link layer drops it
                lk.closed = True

    def _camera_heartbeat(self) -> None:
        """With the autopilot's HEARTBEAT: the camera's own."""
        if self.camera is not None:
            self._camera_send(self._enc.heartbeat_encode(M.MAV_TYPE_CAMERA, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                                         M.MAV_STATE_ACTIVE, 3))

    def _camera_command(self, link: "_Link", msg: Any) -> bool:
        """A COMMAND_LONG addressed to the camera's component: answered here (True), else False."""
        cam = self.camera
        if cam is None or msg.get_type() != "COMMAND_LONG" or msg.target_component != cam.component \
                or msg.target_system not in (0, self.system_id):
            return False
        msg_id = int(msg.param1) if msg.command == M.MAV_CMD_REQUEST_MESSAGE else _ASKS.get(msg.command)
        boot_ms = int(self.boot_ms0 + self.t * 1000.0) & 0xFFFFFFFF
        out = cam.build(msg_id, self._enc, boot_ms) if msg_id is not None else None
        result = M.MAV_RESULT_ACCEPTED if out is not None else M.MAV_RESULT_UNSUPPORTED
        self.camera_requests.append((int(msg.command), int(msg.target_component)))
        self._camera_send(self._enc.command_ack_encode(msg.command, result, 0, 0, msg.get_srcSystem(),
                                                       msg.get_srcComponent()), link)
        if out is not None:
            self._camera_send(out, link)
        return True
