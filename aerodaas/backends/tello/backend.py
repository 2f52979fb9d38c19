"""The DJI Tello vehicle backend: :class:`TelloBackend`, one class composed of the link and control mixins
(see the package docstring), holding the shared state: the dead-reckoned pose, the newest video frame, events."""
from __future__ import annotations

import queue
import socket
import threading
import time
from typing import Any

import numpy as np

from aerodaas.config import TelloConfig
from aerodaas.config.robot import sensor_class
from aerodaas.plugins.sensor import FrameSensor
from aerodaas.model.geo import enu_to_geodetic
from aerodaas.model.types import Attitude, Odometry
from aerodaas.backends.base import VehicleBackend
from aerodaas.backends.tello.control import ControlMixin, _Motion
from aerodaas.backends.tello.link import LinkMixin

__all__ = ["TelloBackend"]


class TelloBackend(LinkMixin, ControlMixin, VehicleBackend):
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
        super().__init__(cfg.id, cfg.home)
        self.cfg: TelloConfig = self.options(cfg)
        self.limits = cfg.limits
        self._state_lock = threading.Lock()
        self._cmd_lock = threading.Lock()
        self._replies: queue.Queue[str] = queue.Queue()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._cmd_sock: socket.socket | None = None
        self._state_sock: socket.socket | None = None
        self._video_sock: socket.socket | None = None
        self._t0 = time.monotonic()
        self._connected = False
        # state (guarded by _state_lock)
        self._pos = np.zeros(3)
        self._vel = np.zeros(3)
        self._yaw_enu = self.enu_yaw_from_heading(self.cfg.initial_heading_deg)
        self._roll = self._pitch = 0.0
        self._bat = 0.0
        self._h_cm = 0.0
        self._yaw_ref: float | None = None  # Tello yaw at connect
        self._last_state: float | None = None  # monotonic arrival of the last good packet
        #: monotonic arrival of the last packet that showed the Tello at rest (0 dm/s, yaw as in the one before)
        self._rest_at: float | None = None
        self._armed = False
        self._frame: tuple[np.ndarray, float] | None = None
        self._link_was_ok = True
        self._events: list[dict[str, Any]] = []
        # control
        self._motion: _Motion | None = None
        self._sticks = (0, 0, 0, 0)
        self._last_send = 0.0
        self.stats = {"commands": 0, "retries": 0, "timeouts": 0, "stale_replies": 0, "state_packets": 0,
                      "malformed_state": 0, "keepalives": 0, "video_datagrams": 0, "video_frames": 0,
                      "video_errors": 0, "video_decode_ms": 0.0, "settle_timeouts": 0}
        #: the Tello's last reply other than ``ok`` (diagnostics)
        self.last_status = ""
        #: ids of the robot's camera sensors with ``properties.source: backend``: they need the video stream
        self._video_sensors = [s.id for s in cfg.sensors
                               if issubclass(sensor_class(s.type), FrameSensor)
                               and s.properties.get("source") == "backend"]

    # ------------------------------------------------------------------ time and state
    @property
    def t(self) -> float:
        return time.monotonic() - self._t0

    def step(self, dt: float) -> None:
        """Non-blocking: turns link changes into ``link_lost``/``link_regained`` events (state arrives on a
        receiver thread)."""
        ok = self.link_ok
        if ok != self._link_was_ok:
            self._link_was_ok = ok
            self._push_event("link_regained" if ok else "link_lost")

    @property
    def link_ok(self) -> bool:
        last = self._last_state
        return last is not None and time.monotonic() - last < self.cfg.state_timeout_s

    @property
    def position(self) -> np.ndarray:
        with self._state_lock:
            return self._pos.copy()

    @property
    def velocity(self) -> np.ndarray:
        with self._state_lock:
            return self._vel.copy()

    @property
    def yaw(self) -> float:
        return float(self._yaw_enu) % 360.0

    @property
    def armed(self) -> bool:
        return self._armed or self.in_air

    @property
    def in_air(self) -> bool:
        """True while the Tello reports a height (``h`` >= 10 cm) above its take-off point."""
        return self._h_cm >= 10.0

    @property
    def battery_pct(self) -> float:
        return float(self._bat)

    def odometry(self) -> Odometry:
        with self._state_lock:
            pos, vel = self._pos.copy(), self._vel.copy()
            roll, pitch, yaw, bat = self._roll, self._pitch, self._yaw_enu % 360.0, self._bat
        geo = enu_to_geodetic(float(pos[0]), float(pos[1]), float(pos[2]), self.home)
        return Odometry(robot_id=self.robot_id, t=self.t, position=tuple(float(v) for v in pos), geodetic=geo,
                        velocity=tuple(float(v) for v in vel), attitude=Attitude(roll=roll, pitch=pitch, yaw=yaw),
                        battery_pct=float(min(max(bat, 0.0), 100.0)), armed=self.armed, in_air=self.in_air)

    def _push_event(self, name: str, **kw: Any) -> None:
        with self._state_lock:
            self._events.append({"event": name, "t": self.t, **kw})

    def drain_events(self) -> list[dict[str, Any]]:
        with self._state_lock:
            out, self._events = self._events, []
        return out

    def camera_frame(self) -> tuple[np.ndarray, float] | None:
        """The newest decoded video frame, ``(720, 960, 3) uint8 BGR`` on a real Tello, and its arrival time
        on :attr:`t`'s clock; None before the first frame, with ``video`` off, or after a refused ``streamon``
        (a ``video_error`` event)."""
        with self._state_lock:
            return self._frame
