"""The Tello link (:class:`TelloLink`): UDP sockets, the receiver threads (command replies, state packets with dead
reckoning, video), the keep-alive, the command channel (one transaction at a time, retries, stale replies drained),
and what the state packets and the video stream say: the dead-reckoned pose, the newest frame, the events."""
from __future__ import annotations

import logging
import math
import queue
import socket
import threading
import time
from typing import Any, Callable, Iterator

import numpy as np

from aerodaas.backends.base import BackendError, CommandRefused, LinkLost, VehicleBackend
from aerodaas.backends.tello.protocol import parse_state
from aerodaas.backends.tello.video import H264Reassembler

#: the package's logger (named ``aerodaas.backends.tello``, as before the package was split)
log = logging.getLogger(__package__)


class _Cancelled(Exception):
    pass


class TelloLink:
    """The link to one Tello (see the module docstring), a concern object of
    :class:`~aerodaas.backends.tello.backend.TelloBackend`. ``cfg``: the robot's
    :class:`~aerodaas.config.TelloConfig`; ``video_sensors``: ids of the robot's camera sensors that read the
    Tello's video (a refused ``streamon`` then fails :meth:`connect`).

    State (the pose guarded by a lock: the state receiver updates it): the sockets and threads, the replies
    waiting, the dead-reckoned position (ENU m), velocity (ENU m/s), yaw (ENU degrees), roll/pitch (degrees),
    battery (%), height ``h`` (cm), when the last state packet came and the last one at rest, the newest video
    frame, the events not yet drained, :attr:`stats` (counters) and :attr:`last_status` (the Tello's last reply
    other than ``ok``). :attr:`sticks` are the virtual sticks the keep-alive re-sends unless :attr:`manoeuvre` (the
    motion worker's thread) runs."""

    def __init__(self, robot_id: str, cfg: Any, video_sensors: list[str]) -> None:
        self.robot_id, self.cfg, self._video_sensors = robot_id, cfg, video_sensors
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
        self._yaw_enu = VehicleBackend.enu_yaw_from_heading(cfg.initial_heading_deg)
        self._roll = self._pitch = 0.0
        self._bat = 0.0
        self._h_cm = 0.0
        self._yaw_ref: float | None = None  # Tello yaw at connect
        self._last_state: float | None = None  # monotonic arrival of the last good packet
        #: monotonic arrival of the last packet that showed the Tello at rest (0 dm/s, yaw as in the one before)
        self._rest_at: float | None = None
        self._frame: tuple[np.ndarray, float] | None = None
        self._events: list[dict[str, Any]] = []
        #: the virtual sticks (``rc a b c d``) the keep-alive re-sends
        self.sticks: tuple[int, int, int, int] = (0, 0, 0, 0)
        #: the motion worker's thread while a manoeuvre may run (control.py): no keep-alive meanwhile
        self.manoeuvre: threading.Thread | None = None
        self._last_send = 0.0
        self.stats = {"commands": 0, "retries": 0, "timeouts": 0, "stale_replies": 0, "state_packets": 0,
                      "malformed_state": 0, "keepalives": 0, "video_datagrams": 0, "video_frames": 0,
                      "video_errors": 0, "video_decode_ms": 0.0, "settle_timeouts": 0}
        #: the Tello's last reply other than ``ok`` (diagnostics)
        self.last_status = ""

    # ------------------------------------------------------------------ time and state
    @property
    def t(self) -> float:
        """Wall seconds since :meth:`connect` (since construction before it)."""
        return time.monotonic() - self._t0

    @property
    def connected(self) -> bool:
        """:meth:`connect` succeeded and :meth:`close` has not run."""
        return self._connected

    @property
    def closed(self) -> bool:
        """:meth:`close` ran: the threads are stopped and released."""
        return self._stop.is_set() and not self._threads

    @property
    def link_ok(self) -> bool:
        """A state packet came within ``state_timeout_s``."""
        last = self._last_state
        return last is not None and time.monotonic() - last < self.cfg.state_timeout_s

    @property
    def position(self) -> np.ndarray:
        """(3,) ENU metres: dead-reckoned x/y, ``h`` as z (a copy)."""
        with self._state_lock:
            return self._pos.copy()

    @property
    def velocity(self) -> np.ndarray:
        """(3,) ENU m/s of the latest state packet (a copy)."""
        with self._state_lock:
            return self._vel.copy()

    @property
    def yaw(self) -> float:
        """ENU yaw, degrees 0..360 (counter-clockwise from east)."""
        return float(self._yaw_enu) % 360.0

    @property
    def height_cm(self) -> float:
        """The state packets' ``h``: centimetres above the take-off point."""
        return self._h_cm

    @property
    def battery_pct(self) -> float:
        """The state packets' ``bat``, percent."""
        return float(self._bat)

    @property
    def rest_at(self) -> float | None:
        """Monotonic arrival of the last state packet showing the Tello at rest (None before one)."""
        return self._rest_at

    def pose(self) -> tuple[np.ndarray, np.ndarray, float, float, float, float]:
        """One consistent reading: position (ENU m), velocity (ENU m/s), roll, pitch, yaw (ENU, 0..360) in
        degrees, battery percent."""
        with self._state_lock:
            return self._pos.copy(), self._vel.copy(), self._roll, self._pitch, self._yaw_enu % 360.0, self._bat

    def correct_horizontal(self, east_m: float, north_m: float) -> None:
        """Set the dead-reckoned horizontal position (the Tello's own estimate after an answered ``go``)."""
        with self._state_lock:
            self._pos[0], self._pos[1] = east_m, north_m

    def event(self, name: str, **fields: Any) -> None:
        """Record an event ``{"event": name, "t": :attr:`t`, **fields}``."""
        with self._state_lock:
            self._events.append({"event": name, "t": self.t, **fields})

    def drain_events(self) -> list[dict[str, Any]]:
        """Every event not yet drained, oldest first."""
        with self._state_lock:
            out, self._events = self._events, []
        return out

    def frame(self) -> tuple[np.ndarray, float] | None:
        """The newest decoded video frame and its arrival time on :attr:`t`'s clock (None before the first)."""
        with self._state_lock:
            return self._frame

    # ------------------------------------------------------------------ lifecycle
    def connect(self, timeout_s: float = 30.0) -> None:
        """Open the sockets, enter SDK mode (``command``), wait for the first state packet and, with
        ``video``, send ``streamon`` (see :meth:`_start_video` for a refusal). Raises :class:`BackendError`
        (naming the robot and the step) after ``timeout_s`` seconds or when a socket cannot be bound, and
        :class:`CommandRefused` when the Tello refuses ``streamon`` while a camera sensor needs its video."""
        c = self.cfg
        deadline = time.monotonic() + timeout_s
        try:
            self._cmd_sock = self._udp(("0.0.0.0", c.local_command_port), "local_command_port")
            self._cmd_sock.connect((c.host, c.command_port))
            self._state_sock = self._udp((c.bind_host, c.state_port), "state_port")
            if c.video:
                self._video_sock = self._udp((c.bind_host, c.video_port), "video_port", rcvbuf=4 << 20)
        except BackendError:
            self.close()
            raise
        except OSError as e:
            self.close()
            raise BackendError(f"robot {self.robot_id!r}: connect: cannot reach {c.host}:{c.command_port}: {e}") from e
        self._t0 = time.monotonic()
        self._spawn(self._reply_loop, "replies")
        self._spawn(self._state_loop, "state")
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self.close()
                raise BackendError(f"robot {self.robot_id!r}: connect: no 'ok' to 'command' from "
                                   f"{c.host}:{c.command_port} within {timeout_s} s")
            try:
                if self.transact("command", min(c.command_timeout_s, left), retries=0) == "ok":
                    break
            except BackendError:
                continue
        while self._last_state is None:
            if time.monotonic() > deadline:
                self.close()
                raise BackendError(f"robot {self.robot_id!r}: connect: no state packet on port {c.state_port} "
                                   f"within {timeout_s} s")
            time.sleep(0.02)
        if c.video:
            self._spawn(self._video_loop, "video")
            self._start_video()
        self._spawn(self._keepalive_loop, "keepalive")
        self._connected = True

    def _start_video(self) -> None:
        """``streamon``, checking its reply. A refusal (``error``, ``out of range``...) or no reply after the
        retries fails the connection (the backend is closed; CommandRefused with the Tello's reply, or
        BackendError) when a camera sensor of this robot has ``properties.source: backend``; otherwise the robot
        flies without video: a ``video_error`` event (``command``, ``reply``, ``reason``), a warning in the log,
        and :meth:`frame` stays None."""
        c = self.cfg
        reply: str | None = None
        try:
            reply = self.transact("streamon", c.command_timeout_s, retries=c.command_retries)
        except BackendError as e:
            failure = str(e)
        else:
            if reply.lower() == "ok":
                return
            self.last_status = reply
            failure = f"robot {self.robot_id!r}: streamon refused: {reply}"
        if self._video_sensors:
            needs = (f"sensors {', '.join(repr(i) for i in self._video_sensors)}: a camera with "
                     "properties.source 'backend' needs the Tello's video")
            self.close()
            if reply is not None:
                raise CommandRefused(self.robot_id, "streamon", reply, needs)
            raise BackendError(f"{failure}; {needs}")
        self.event("video_error", command="streamon", reply=reply, reason=failure)
        log.warning("%s; flying without video (set tello.video to false if none is wanted)", failure)

    def close(self) -> None:
        """Stop the threads and close the sockets (idempotent, never raises). Does not land the Tello."""
        self._stop.set()
        for s in (self._cmd_sock, self._state_sock, self._video_sock):
            if s is not None:
                try:
                    s.close()
                except OSError:
                    pass
        for th in self._threads:
            if th is not threading.current_thread():
                th.join(timeout=2.0)
        self._threads.clear()
        self._connected = False

    def _udp(self, addr: tuple[str, int], field_name: str, rcvbuf: int = 0) -> socket.socket:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # no SO_REUSEADDR: a port in use is an error
        if rcvbuf:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        s.settimeout(0.1)
        try:
            s.bind(addr)
        except OSError as e:
            s.close()
            raise BackendError(f"robot {self.robot_id!r}: connect: cannot bind tello.{field_name} "
                               f"{addr[0]}:{addr[1]}: {e}") from e
        return s

    def _spawn(self, fn: Callable[[], None], name: str) -> None:
        th = threading.Thread(target=fn, name=f"tello-{self.robot_id}-{name}", daemon=True)
        th.start()
        self._threads.append(th)

    # ------------------------------------------------------------------ receivers
    def _datagrams(self, sock: socket.socket, size: int) -> Iterator[bytes]:
        """Datagrams from ``sock`` until :meth:`close` (socket errors such as an ICMP port-unreachable surfacing as
        ConnectionRefusedError are skipped)."""
        while not self._stop.is_set():
            try:
                yield sock.recv(size)
            except socket.timeout:
                continue
            except OSError:
                if self._stop.is_set():
                    return
                time.sleep(0.05)

    def _reply_loop(self) -> None:
        for data in self._datagrams(self._cmd_sock, 2048):
            self._replies.put(data.decode("utf-8", "replace").strip())

    def _state_loop(self) -> None:
        prev_v: np.ndarray | None = None
        prev_yaw: float | None = None
        for data in self._datagrams(self._state_sock, 2048):
            now = time.monotonic()
            try:
                st = parse_state(data)
            except ValueError as e:
                self.stats["malformed_state"] += 1
                log.debug("robot %s: skipped malformed Tello state packet: %s", self.robot_id, e)
                continue
            self.stats["state_packets"] += 1
            with self._state_lock:
                if self._yaw_ref is None:
                    self._yaw_ref = st["yaw"]
                heading = self.cfg.initial_heading_deg + (st["yaw"] - self._yaw_ref)
                v = self._enu_velocity(st, heading)
                if self._last_state is not None and prev_v is not None:
                    dt = min(now - self._last_state, 0.5)  # a gap is a lost link, not a long flight
                    self._pos[:2] += 0.5 * (prev_v[:2] + v[:2]) * dt
                prev_v = v
                self._last_state = now
                if st["vgx"] == st["vgy"] == st["vgz"] == 0 and st["yaw"] == prev_yaw:
                    self._rest_at = now
                prev_yaw = st["yaw"]
                self._pos[2] = st["h"] / 100.0
                self._h_cm = st["h"]
                self._vel = v
                self._yaw_enu = VehicleBackend.enu_yaw_from_heading(heading)
                self._roll, self._pitch = st["roll"], st["pitch"]
                self._bat = st["bat"]

    def _enu_velocity(self, st: dict[str, float], heading_deg: float) -> np.ndarray:
        """ENU m/s from vgx/vgy/vgz (dm/s, NED-like; x along yaw 0 or the body's forward axis, see module doc)."""
        if self.cfg.velocity_frame == "body":
            h = math.radians(heading_deg)
        else:
            h = math.radians(self.cfg.initial_heading_deg - self._yaw_ref)
        vx, vy, vz = st["vgx"] / 10.0, st["vgy"] / 10.0, st["vgz"] / 10.0
        north = vx * math.cos(h) - vy * math.sin(h)
        east = vx * math.sin(h) + vy * math.cos(h)
        return np.array([east, north, -vz])

    def _video_loop(self) -> None:
        try:
            dec = H264Reassembler()
        except ImportError as e:
            self.event("video_error", reason=f"PyAV is not installed: {e}")
            return
        for data in self._datagrams(self._video_sock, 65536):
            self.stats["video_datagrams"] += 1
            frames = dec.feed(data)
            self.stats["video_errors"] = dec.errors
            if frames:
                t = time.monotonic() - self._t0
                with self._state_lock:
                    self._frame = (frames[-1], t)
                self.stats["video_frames"] = dec.frames
                self.stats["video_decode_ms"] = 1000.0 * dec.decode_s / max(dec.frames, 1)

    def _keepalive_loop(self) -> None:
        period = self.cfg.keepalive_s
        while not self._stop.wait(min(0.1, period / 4)):
            m = self.manoeuvre
            if m is not None and m.is_alive():
                continue  # the Tello is busy with a manoeuvre; its 15 s count starts when it finishes
            if time.monotonic() - self._last_send >= period:
                self.send_rc(self.sticks)
                self.stats["keepalives"] += 1

    # ------------------------------------------------------------------ command channel
    def send(self, cmd: str) -> None:
        """Send ``cmd`` without waiting for a reply. Raises LinkLost when not connected or the send fails."""
        if self._cmd_sock is None:
            raise LinkLost(f"robot {self.robot_id!r}: {cmd}: not connected (call connect() first)")
        try:
            self._cmd_sock.send(cmd.encode("utf-8"))
        except OSError as e:
            raise LinkLost(f"robot {self.robot_id!r}: {cmd}: cannot send to the Tello: {e}") from e
        self._last_send = time.monotonic()
        self.stats["commands"] += 1

    def send_rc(self, sticks: tuple[int, int, int, int]) -> None:
        """``rc a b c d`` with ``sticks`` (-100..100 each); a failed send is logged, not raised."""
        try:
            self.send("rc {} {} {} {}".format(*sticks))
        except LinkLost as e:
            log.debug("%s", e)

    def transact(self, cmd: str, timeout_s: float, retries: int, cancel: threading.Event | None = None) -> str:
        """Send ``cmd`` and return the Tello's reply (stripped). A missing reply is retried ``retries`` times;
        then :class:`LinkLost` (no state either) or :class:`BackendError`. ``cancel`` aborts the wait
        (raises :class:`_Cancelled`). One transaction at a time: the protocol has no sequence numbers, so stale
        replies are drained before each send."""
        with self._cmd_lock:
            for attempt in range(retries + 1):
                while True:
                    try:
                        self._replies.get_nowait()
                        self.stats["stale_replies"] += 1
                    except queue.Empty:
                        break
                if attempt:
                    self.stats["retries"] += 1
                self.send(cmd)
                deadline = time.monotonic() + timeout_s
                while True:
                    left = deadline - time.monotonic()
                    if cancel is not None and cancel.is_set():
                        raise _Cancelled(cmd)
                    if left <= 0:
                        break
                    try:
                        return self._replies.get(timeout=min(left, 0.05))
                    except queue.Empty:
                        continue
                self.stats["timeouts"] += 1
        if not self.link_ok:
            raise LinkLost(f"robot {self.robot_id!r}: {cmd}: no reply after {retries + 1} tries and no state "
                           f"packet for {self.cfg.state_timeout_s} s")
        raise BackendError(f"robot {self.robot_id!r}: {cmd}: no reply from the Tello after {retries + 1} tries "
                           f"of {timeout_s:.1f} s")

    def expect_ok(self, cmd: str, reply: str) -> None:
        """Raises CommandRefused (the Tello's reply, kept as :attr:`last_status`) unless ``reply`` is ``ok``."""
        if reply.lower() != "ok":
            self.last_status = reply
            raise CommandRefused(self.robot_id, cmd, reply)

    def command(self, cmd: str) -> str:
        """Send any SDK command and return its reply (e.g. ``battery?`` -> ``"87"``), with retries; waits while a
        manoeuvre is being executed (one command at a time). Raises :class:`CommandRefused` for
        ``error...``/``out of range``/``unknown command`` replies, BackendError / LinkLost without reply."""
        reply = self.transact(cmd, self.cfg.command_timeout_s, self.cfg.command_retries)
        low = reply.lower()
        if low.startswith(("error", "out of range", "unknown command")):
            self.last_status = reply
            raise CommandRefused(self.robot_id, cmd, reply)
        return reply
