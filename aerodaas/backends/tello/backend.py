"""The DJI Tello vehicle backend: :class:`TelloBackend`, composed of its link (:class:`~.link.TelloLink`: sockets,
receivers, the dead-reckoned state, the video) and its flight control (:class:`~.control.TelloControl`), each
given what it needs (see the package docstring)."""
from __future__ import annotations

from typing import Any


from aerodaas.config import TelloConfig
from aerodaas.config.robot import sensor_class
from aerodaas.backends.base import VehicleBackend, VehicleState
from aerodaas.backends.tello.control import TelloControl
from aerodaas.backends.tello.link import TelloLink

__all__ = ["TelloBackend"]


class TelloBackend(VehicleBackend):
    """A DJI Tello over the SDK 2.0 UDP protocol (see the package docstring for the protocol and conventions).

    Threads: a reply receiver (command socket), a state receiver (parses packets, dead-reckons, watches the
    link), a video receiver/decoder (keeps only the newest frame), a keep-alive timer, and one motion worker at a
    time. Motion methods (:meth:`takeoff`, :meth:`goto`, :meth:`land`) start the worker and return once the first
    command has not been refused within ``accept_window_s`` (refusal: :class:`CommandRefused` with the Tello's
    reply); later failures become ``command_failed`` events. A new motion, :meth:`hold` or :meth:`set_velocity`
    pre-empts the running one with ``stop``.

    Retries: a read/set command without reply after ``command_timeout_s`` is re-sent up to ``command_retries``
    times. Motion commands are never re-sent blindly (a repeated relative ``go`` would fly twice as far):
    ``goto`` recomputes the remaining offset from the dead-reckoned position before each ``go``, ``takeoff``
    and ``land`` check the state packets first.
    """

    kind = "tello"
    clock = "vehicle"
    Config = TelloConfig
    config_section = "tello"
    provides_camera = True  # the Tello's H.264 video stream (video.py)

    def __init__(self, cfg) -> None:  # cfg: aerodaas.config.RobotConfig
        """The link and the flight control, each given its collaborators (see :class:`TelloLink`,
        :class:`TelloControl`)."""
        super().__init__(cfg.id, cfg.home)
        self.cfg: TelloConfig = self.options(cfg)
        self.limits = cfg.limits
        #: ids of the robot's camera sensors with ``properties.source: backend``: they need the video stream
        video_sensors = [s.id for s in cfg.sensors
                         if sensor_class(s.type).delivery.frames
                         and s.properties.get("source") == "backend"]
        #: sockets, receivers, keep-alive, command channel, the dead-reckoned state and the video (link.py)
        self.link = TelloLink(self.robot_id, self.cfg, video_sensors)
        #: the motion worker and the flight commands (control.py): the command groups ``actions`` and ``guidance``
        self.control = TelloControl(self.robot_id, self.cfg, self.limits, self.link)
        self.actions = self.guidance = self.control
        #: the camera (:meth:`TelloLink.frame`: the newest decoded frame, ``(720, 960, 3) uint8 BGR`` on a real
        #: Tello, and its arrival time on :attr:`t`'s clock; None before the first, with ``video`` off, or after a
        #: refused ``streamon``, a ``video_error`` event)
        self.camera = self.link
        self._link_was_ok: bool | None = None  # the link as last seen (None: not connected yet)
        self._events: list[dict[str, Any]] = []  # link changes not yet drained

    # ------------------------------------------------------------------ lifecycle, time and state
    def connect(self, timeout_s: float = 30.0) -> None:
        """:meth:`TelloLink.connect`, then watch the link from its state now (``link_lost`` / ``link_regained``
        events from here on, :meth:`step`). Raises what :meth:`TelloLink.connect` raises."""
        self.link.connect(timeout_s)
        self._link_was_ok = self.link.link_ok

    def close(self) -> None:
        """Cancel a running manoeuvre, then :meth:`TelloLink.close` (idempotent, never raises; does not land)."""
        self.control.cancel()
        self.link.close()

    def step(self, dt: float) -> None:
        """Non-blocking: turns link changes into ``link_lost``/``link_regained`` events (state arrives on a
        receiver thread)."""
        ok = self.link.link_ok
        if self._link_was_ok is not None and ok != self._link_was_ok:
            self._link_was_ok = ok
            self._events.append({"event": "link_regained" if ok else "link_lost", "t": self.link.t})

    def state(self) -> VehicleState:
        """The dead-reckoned pose, attitude and battery of one reading (:meth:`TelloLink.pose`) at :attr:`TelloLink.t`;
        armed while marked armed (:attr:`TelloControl.armed`) or in the air; in the air while the Tello reports a
        height (``h``) of at least 10 cm above its take-off point; the link is up while state packets come
        (:attr:`TelloLink.link_ok`)."""
        pos, vel, roll, pitch, yaw, bat = self.link.pose()
        in_air = self.link.height_cm >= 10.0
        return VehicleState(t=self.link.t, position=pos, velocity=vel, roll=roll, pitch=pitch, yaw=yaw,
                            battery_pct=float(bat), armed=self.control.armed or in_air, in_air=in_air,
                            link_ok=self.link.link_ok, home=self.home)

    def drain_events(self) -> list[dict[str, Any]]:
        """The link's events (:meth:`TelloLink.drain_events`: command failures, video errors...) and the link
        changes :meth:`step` saw, in time order (``t``), oldest first."""
        own, self._events = self._events, []
        return sorted(self.link.drain_events() + own, key=lambda e: e["t"])
