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


class CameraHost:
    """The camera component slot of the emulated vehicle's system ``system_id`` (none attached by default):
    :meth:`attach` puts a camera there, :meth:`heartbeat` sends its HEARTBEAT with the autopilot's and
    :meth:`answer` replies to the COMMAND_LONGs addressed to its component. ``enc``: the vehicle's MAVLink encoder
    (messages are built with it and sent with the camera's own per-link encoders). Not locked: the vehicle calls it
    under its lock."""

    def __init__(self, system_id: int, enc: Any) -> None:
        self.system_id, self._enc = system_id, enc
        #: the attached camera (None: none)
        self.camera: "EmulatedCamera | None" = None
        self._mavs: dict[int, Any] = {}
        #: (command, component asked) of every request the camera answered
        self.requests: list[tuple[int, int]] = []

    def attach(self, camera: "EmulatedCamera | None") -> None:
        """Put ``camera`` on the vehicle's system (None takes it away): its HEARTBEAT starts with the next one
        of the autopilot, and it answers requests addressed to its component id; the request log starts empty."""
        self.camera = camera
        self._mavs = {}
        self.requests = []

    def _send(self, msg: Any, links: "list[_Link]") -> None:
        """Send ``msg`` from the camera's component on each of ``links`` (a closed link is marked closed)."""
        for lk in links:
            mav = self._mavs.get(id(lk))
            if mav is None:
                mav = self._mavs[id(lk)] = M.MAVLink(lk, srcSystem=self.system_id,
                                                     srcComponent=self.camera.component)
            try:
                mav.send(msg)
            except Exception:  # noqa: BLE001 - a closed link: the link layer drops it
                lk.closed = True

    def heartbeat(self, links: "list[_Link]") -> None:
        """With the autopilot's HEARTBEAT: the camera's own on every one of ``links`` (nothing without a camera)."""
        if self.camera is not None:
            self._send(self._enc.heartbeat_encode(M.MAV_TYPE_CAMERA, M.MAV_AUTOPILOT_INVALID, 0, 0,
                                                  M.MAV_STATE_ACTIVE, 3), list(links))

    def answer(self, link: "_Link", msg: Any, boot_ms: int) -> bool:
        """A COMMAND_LONG ``msg`` from ``link`` addressed to the camera's component: answered here (a COMMAND_ACK,
        then the message asked for, stamped ``boot_ms`` ms since boot), True; anything else False."""
        cam = self.camera
        if cam is None or msg.get_type() != "COMMAND_LONG" or msg.target_component != cam.component \
                or msg.target_system not in (0, self.system_id):
            return False
        msg_id = int(msg.param1) if msg.command == M.MAV_CMD_REQUEST_MESSAGE else _ASKS.get(msg.command)
        out = cam.build(msg_id, self._enc, boot_ms) if msg_id is not None else None
        result = M.MAV_RESULT_ACCEPTED if out is not None else M.MAV_RESULT_UNSUPPORTED
        self.requests.append((int(msg.command), int(msg.target_component)))
        self._send(self._enc.command_ack_encode(msg.command, result, 0, 0, msg.get_srcSystem(),
                                                msg.get_srcComponent()), [link])
        if out is not None:
            self._send(out, [link])
        return True
