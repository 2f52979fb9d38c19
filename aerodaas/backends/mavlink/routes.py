"""What the link (:class:`~aerodaas.backends.mavlink.link.MavlinkLink`) hands on to the concerns made on it, as typed
receivers: as in MAVSDK, where each plugin is given the ``System`` and subscribes to the messages it needs, each
concern registers itself with the link when it is made (``MavlinkLink.serve_commands`` and the like). A receiver is
called on the link's I/O thread."""
from __future__ import annotations

from typing import Any, Protocol


class CommandRoute(Protocol):
    """The command protocol (command.py :class:`~aerodaas.backends.mavlink.command.CommandProtocol`): COMMAND_ACKs
    (wall time ``now``, the message), the mode we last asked for (``(name, monotonic)``, or None: a mode change to it
    is no failsafe), and COMMAND_LONG with its acknowledgement awaited (the link's stream and HOME_POSITION requests;
    raises as :meth:`CommandProtocol.command_long`)."""

    @property
    def mode_asked(self) -> tuple[str, float] | None: ...

    def on_command_ack(self, now: float, msg: Any) -> None: ...

    def command_long(self, name: str, command: int, *params: float, retries: int | None = None,
                     timeout_s: float | None = None) -> None: ...


class MissionRoute(Protocol):
    """The mission protocol's transfers (transfer.py :class:`~aerodaas.backends.mavlink.transfer.MissionTransfer`):
    each MISSION_REQUEST(_INT), MISSION_ACK, MISSION_COUNT and MISSION_ITEM(_INT) received."""

    def offer(self, msg: Any) -> None: ...


class ComponentRoute(Protocol):
    """A receiver of every message of the vehicle's system, whichever component sent it (camera.py
    :class:`~aerodaas.backends.mavlink.camera.CameraFinder`)."""

    def on_message(self, msg: Any) -> None: ...


class SetpointStream(Protocol):
    """The guided target the I/O thread streams (offboard.py
    :class:`~aerodaas.backends.mavlink.offboard.OffboardControl`): the active target (None: no stream; read under
    the backend's lock), PX4's offboard-loss timeout (vehicle seconds: the most time between two sends),
    ``send_due(setpoint, now)`` (send it when due, ``now`` wall time) and ``stop_quiet()`` (the autopilot entered a
    failsafe: stop streaming, no event)."""

    @property
    def setpoint(self) -> tuple | None: ...

    @property
    def loss_timeout_s(self) -> float: ...

    def send_due(self, sp: tuple, now: float) -> None: ...

    def stop_quiet(self) -> None: ...


class StreamSource(Protocol):
    """A concern asking for more telemetry: ``streams()`` gives (MAVLink message id, Hz) pairs requested with the
    link's own (gimbal.py :class:`~aerodaas.backends.mavlink.gimbal.GimbalConcern`)."""

    def streams(self) -> tuple: ...
