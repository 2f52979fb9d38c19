"""DJI Tello backend: Tello SDK 2.0 text commands over UDP, state packets, and the H.264 video stream.

Protocol (Ryze Tech, *Tello SDK 2.0 User Guide*, V1.0 2018-11):

* **Commands** are UTF-8 text datagrams to the Tello's UDP port 8889; the reply comes back to the sending
  socket: ``ok``, ``error`` (optionally with a reason, e.g. ``error Motor stop``), ``out of range`` or, for read
  commands (``battery?``), the value. ``command`` enters SDK mode and must come first. ``takeoff``, ``land``,
  ``go x y z speed``, ``up x`` ... are answered only when the Tello has *finished* the manoeuvre. ``stop`` (hover)
  works at any time. ``rc a b c d`` sets the four virtual sticks (a: left/right, b: forward/backward, c: up/down,
  d: yaw, each -100..100); Tellos do not answer it in practice, so it is sent without waiting.
  ``go x y z speed``: body frame, x forward, y left, z up, in cm (-500..500, not all three within -20..20 at once),
  speed 10..100 cm/s. ``up``/``down x``: 20..500 cm.
* **State**: after ``command``, the Tello sends ``pitch:%d;roll:%d;yaw:%d;vgx:%d;vgy:%d;vgz:%d;templ:%d;temph:%d;
  tof:%d;h:%d;bat:%d;baro:%.2f;time:%d;agx:%.2f;agy:%.2f;agz:%.2f;\\r\\n`` to UDP 8890 of the host at about
  10 Hz (the Tello EDU prefixes mission-pad fields ``mid;x;y;z;mpry``, which we ignore). pitch/roll/yaw in degrees
  (yaw clockwise-positive, -180..180, relative to the heading at power-on: the Tello has no compass), ``h`` height
  above the take-off point in cm, ``bat`` percent, ``tof`` ToF distance to the ground in cm, ``baro`` metres,
  ``time`` motor-on seconds, ``ag*`` acceleration in 0.001 g.
* **Video**: after ``streamon``, raw H.264 (Annex B) to UDP 11111 of the host. Each encoded frame is cut into
  datagrams of 1460 bytes, the last one shorter; DJI's own ``Tello-Python/Tello_Video`` sample reassembles a frame
  by that rule and so do we.
* **Safety**: the Tello lands by itself when it receives no command for 15 s after finishing the last one; we send
  ``rc`` with the current sticks every ``keepalive_s`` seconds when no manoeuvre is in progress.

What the guide does not say, and what we assume (each a :class:`~aerodaas.config.TelloConfig` field where it can
differ): ``vgx/vgy/vgz`` are in **dm/s** (measured by users, DJITelloPy issue #96), in a NED-like frame whose x
points along the heading of yaw 0 (``velocity_frame="yaw_zero"``, the ``north_speed/east_speed`` naming of the
Tello's low-level flight data) — ``"body"`` reads them as forward/right instead; ``vgz`` is positive down.

Odometry: the Tello has no GPS. x/y are dead-reckoned by integrating the state velocities (trapezoid rule over the
packets' arrival times), z is ``h``; yaw is converted to ENU with the mission-start reference
``TelloConfig.initial_heading_deg`` (the heading the Tello faces when :meth:`TelloBackend.connect` runs). The
geodetic fix is home + ENU, so it drifts like the dead reckoning does.
"""
from __future__ import annotations

import logging
import math
import queue
import socket
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from ..config import TelloConfig
from ..geo import enu_to_geodetic
from ..models import Attitude, Odometry
from .base import BackendError, CommandRefused, LinkLost, VehicleBackend

__all__ = ["TelloBackend", "parse_state", "go_command", "H264Reassembler", "DATAGRAM_SIZE", "GO_MIN_CM", "GO_MAX_CM"]

log = logging.getLogger(__name__)

#: payload size of a full Tello video datagram; a shorter one ends a frame
DATAGRAM_SIZE = 1460
#: ``go``: each of x, y, z within -500..500 cm, not all three within -20..20 cm at once
GO_MIN_CM, GO_MAX_CM = 20, 500
#: ``go`` speed range, cm/s
GO_SPEED_CM = (10, 100)
#: wall seconds a manoeuvre waits, after the sticks were released, for a state packet showing the Tello at rest
#: (velocity fields 0 dm/s, yaw unchanged); the body-frame ``go`` offset is computed from that pose
SETTLE_S = 1.5
#: the state fields a packet must carry for us to use it
REQUIRED_STATE_FIELDS = ("pitch", "roll", "yaw", "vgx", "vgy", "vgz", "h", "bat")


def parse_state(data: bytes | str) -> dict[str, float]:
    """Parse one Tello state datagram (``key:value;`` pairs, see the module docstring) into ``{key: float}``.

    Mission-pad attitude ``mpry`` (three comma-separated values) is skipped; every other value must be a finite
    number and the fields in :data:`REQUIRED_STATE_FIELDS` must be present. Raises ValueError naming the problem
    (not ASCII, a field without ``:``, a non-numeric value, missing fields)."""
    if isinstance(data, (bytes, bytearray)):
        try:
            text = bytes(data).decode("ascii")
        except UnicodeDecodeError:
            raise ValueError(f"state packet is not ASCII: {bytes(data)[:40]!r}") from None
    else:
        text = data
    text = text.strip()
    if not text:
        raise ValueError("empty state packet")
    out: dict[str, float] = {}
    for item in text.split(";"):
        item = item.strip()
        if not item:
            continue
        key, sep, val = item.partition(":")
        if not sep:
            raise ValueError(f"state field {item!r} has no ':'")
        key = key.strip()
        if key == "mpry":
            continue
        try:
            v = float(val)
        except ValueError:
            raise ValueError(f"state field {key!r}: value {val!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"state field {key!r}: value {val!r} is not finite")
        out[key] = v
    missing = [k for k in REQUIRED_STATE_FIELDS if k not in out]
    if missing:
        raise ValueError(f"state packet lacks fields {missing}: {text[:80]!r}")
    return out


def go_command(offset_enu: Sequence[float], yaw_enu_deg: float, speed_cm: int) -> str | None:
    """The SDK ``go x y z speed`` towards ``offset_enu`` (ENU metres from the vehicle) for a vehicle with ENU yaw
    ``yaw_enu_deg``: body frame x forward, y left, z up, in cm. An offset beyond 500 cm on some axis is scaled
    down along the same straight line (the first chunk of the leg). None when every axis is within the 20 cm the
    command cannot resolve (the SDK refuses x, y, z all within -20..20). ``speed_cm`` is clipped to 10..100 cm/s."""
    d = np.asarray(offset_enu, float)
    yaw = math.radians(yaw_enu_deg)
    fwd = d[0] * math.cos(yaw) + d[1] * math.sin(yaw)
    left = -d[0] * math.sin(yaw) + d[1] * math.cos(yaw)
    body = np.array([fwd, left, d[2]]) * 100.0
    peak = float(np.max(np.abs(body)))
    if peak <= GO_MIN_CM:
        return None
    x, y, z = (int(round(c)) for c in body * min(1.0, GO_MAX_CM / peak))
    if max(abs(x), abs(y), abs(z)) <= GO_MIN_CM:  # rounding brought it back into the dead zone
        return None
    return f"go {x} {y} {z} {int(np.clip(speed_cm, *GO_SPEED_CM))}"


class H264Reassembler:
    """Decodes the Tello's H.264 UDP stream to BGR frames with PyAV (FFmpeg's ``h264`` decoder).

    :meth:`feed` takes one datagram; datagrams are concatenated until one shorter than :data:`DATAGRAM_SIZE`
    ends the frame (the Tello's packetisation), and the access unit is decoded as one packet, so a frame is
    available as soon as its last datagram arrives (no parser look-ahead). Returns the decoded frames,
    each ``(H, W, 3) uint8 BGR``. Undecodable data (e.g. P-frames before the first key frame, a lost datagram)
    is counted in :attr:`errors` and dropped. :attr:`decode_s` accumulates decode + colour-conversion time."""

    MAX_FRAME_BYTES = 4 << 20

    def __init__(self) -> None:
        import av  # lazy: only a Tello with video needs PyAV

        self._av = av
        self._codec = av.CodecContext.create("h264", "r")
        self._buf = bytearray()
        self.errors = 0
        self.frames = 0
        self.decode_s = 0.0

    def feed(self, datagram: bytes) -> list[np.ndarray]:
        self._buf += datagram
        if len(datagram) >= DATAGRAM_SIZE:
            if len(self._buf) > self.MAX_FRAME_BYTES:  # never saw a short datagram: not a Tello stream
                self._buf.clear()
                self.errors += 1
            return []
        data, self._buf = bytes(self._buf), bytearray()
        t0 = time.perf_counter()
        out = []
        try:
            for frame in self._codec.decode(self._av.Packet(data)):
                out.append(frame.to_ndarray(format="bgr24"))
        except self._av.FFmpegError:
            self.errors += 1
        self.decode_s += time.perf_counter() - t0
        self.frames += len(out)
        return out


@dataclass
class _Motion:
    """A manoeuvre run by the motion worker: its name, cancel flag, and how its first command went."""

    name: str
    cancel: threading.Event = field(default_factory=threading.Event)
    settled: threading.Event = field(default_factory=threading.Event)  # first command answered (or failed)
    lock: threading.Lock = field(default_factory=threading.Lock)
    returned: bool = False  # the caller has returned: later errors become events
    error: BackendError | None = None
    thread: threading.Thread | None = None


class _Cancelled(Exception):
    pass


class TelloBackend(VehicleBackend):
    """A DJI Tello over the SDK 2.0 UDP protocol (see the module docstring for the protocol and conventions).

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

    def __init__(self, cfg) -> None:  # cfg: aerodaas.config.RobotConfig
        super().__init__(cfg.id, cfg.home)
        self.cfg: TelloConfig = cfg.tello or TelloConfig()
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
                               if s.type == "camera" and s.properties.get("source") == "backend"]

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
                if self._transact("command", min(c.command_timeout_s, left), retries=0) == "ok":
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
        and :meth:`camera_frame` stays None."""
        c = self.cfg
        reply: str | None = None
        try:
            reply = self._transact("streamon", c.command_timeout_s, retries=c.command_retries)
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
        self._push_event("video_error", command="streamon", reply=reply, reason=failure)
        log.warning("%s; flying without video (set tello.video to false if none is wanted)", failure)

    def close(self) -> None:
        """Stop the threads and close the sockets (idempotent, never raises). Does not land the Tello."""
        m = self._motion
        if m is not None:
            m.cancel.set()
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
                self._yaw_enu = self.enu_yaw_from_heading(heading)
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
            self._push_event("video_error", reason=f"PyAV is not installed: {e}")
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
            m = self._motion
            if m is not None and m.thread is not None and m.thread.is_alive():
                continue  # the Tello is busy with a manoeuvre; its 15 s count starts when it finishes
            if time.monotonic() - self._last_send >= period:
                self._send_rc(self._sticks)
                self.stats["keepalives"] += 1

    # ------------------------------------------------------------------ command channel
    def _send(self, cmd: str) -> None:
        if self._cmd_sock is None:
            raise LinkLost(f"robot {self.robot_id!r}: {cmd}: not connected (call connect() first)")
        try:
            self._cmd_sock.send(cmd.encode("utf-8"))
        except OSError as e:
            raise LinkLost(f"robot {self.robot_id!r}: {cmd}: cannot send to the Tello: {e}") from e
        self._last_send = time.monotonic()
        self.stats["commands"] += 1

    def _send_rc(self, sticks: tuple[int, int, int, int]) -> None:
        try:
            self._send("rc {} {} {} {}".format(*sticks))
        except LinkLost as e:
            log.debug("%s", e)

    def _transact(self, cmd: str, timeout_s: float, retries: int, cancel: threading.Event | None = None) -> str:
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
                self._send(cmd)
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

    def _expect_ok(self, cmd: str, reply: str) -> None:
        if reply.lower() != "ok":
            self.last_status = reply
            raise CommandRefused(self.robot_id, cmd, reply)

    def command(self, cmd: str) -> str:
        """Send any SDK command and return its reply (e.g. ``battery?`` -> ``"87"``), with retries; waits while a
        manoeuvre is being executed (one command at a time). Raises :class:`CommandRefused` for
        ``error...``/``out of range``/``unknown command`` replies, BackendError / LinkLost without reply."""
        reply = self._transact(cmd, self.cfg.command_timeout_s, self.cfg.command_retries)
        low = reply.lower()
        if low.startswith(("error", "out of range", "unknown command")):
            self.last_status = reply
            raise CommandRefused(self.robot_id, cmd, reply)
        return reply

    # ------------------------------------------------------------------ motion worker
    def _motion_timeout(self, distance_m: float, speed_mps: float) -> float:
        return self.cfg.command_timeout_s + 1.5 * distance_m / max(speed_mps, 0.1)

    def _start_motion(self, name: str, plan: Callable[[_Motion], None]) -> None:
        self._require_link(name)
        # a manoeuvre that was stopped, or sticks released, leave the Tello braking: the plan waits for rest first
        released = time.monotonic() if self._preempt() else None
        if any(self._sticks):  # else the keep-alive would resume the old velocity after the manoeuvre
            self._sticks = (0, 0, 0, 0)
            self._send_rc(self._sticks)
            released = time.monotonic()
        m = _Motion(name)

        def run() -> None:
            try:
                if released is not None:
                    self._await_rest(m, released)
                plan(m)
            except _Cancelled:
                pass
            except BackendError as e:
                with m.lock:
                    if not m.returned:  # the caller raises it
                        m.error = e
                    else:
                        self._push_event("command_failed", command=name, error=str(e))
            finally:
                m.settled.set()

        m.thread = threading.Thread(target=run, name=f"tello-{self.robot_id}-{name}", daemon=True)
        self._motion = m
        m.thread.start()
        # the caller hears a refusal of the first command, also when it comes after the wait for rest
        m.settled.wait(self.cfg.accept_window_s + (SETTLE_S if released is not None else 0.0))
        with m.lock:
            m.returned = True
            if m.error is not None:
                raise m.error

    def _await_rest(self, m: _Motion, since: float) -> None:
        """After the sticks were released or a manoeuvre stopped (at monotonic ``since``): wait up to :data:`SETTLE_S` for a state packet
        received after it that shows the Tello at rest, so that a ``go`` offset (body frame, from the current
        yaw and dead-reckoned position) is computed from where it stopped, not from a pose it is braking out of.
        Goes on after the bound (the ``go`` then starts from the latest estimate); raises _Cancelled if pre-empted."""
        end = since + SETTLE_S
        while time.monotonic() < end:
            if m.cancel.is_set():
                raise _Cancelled()
            rest = self._rest_at
            if rest is not None and rest > since:
                return
            time.sleep(0.01)
        self.stats["settle_timeouts"] += 1

    def _motion_step(self, m: _Motion, cmd: str, timeout_s: float) -> str | None:
        """One manoeuvre command: the reply, or None when it went unanswered (the plan re-checks the state)."""
        try:
            reply = self._transact(cmd, timeout_s, retries=0, cancel=m.cancel)
        except LinkLost:
            raise
        except BackendError:
            return None
        if reply.lower() != "ok":
            self.last_status = reply
            raise CommandRefused(self.robot_id, cmd, reply)
        m.settled.set()
        return reply

    def _retry_until(self, m: _Motion, cmd: str, timeout_s: float, done: Callable[[], bool]) -> None:
        for attempt in range(self.cfg.command_retries + 1):
            if attempt:
                self.stats["retries"] += 1
            if self._motion_step(m, cmd, timeout_s) is not None or done():
                return
        raise BackendError(f"robot {self.robot_id!r}: {cmd}: no reply after {self.cfg.command_retries + 1} tries "
                           f"and the state shows it did not happen")

    def _preempt(self) -> bool:
        """Stop the running manoeuvre (cancel its worker, ``stop``); True if one was running."""
        m = self._motion
        if m is None or m.thread is None or not m.thread.is_alive():
            return False
        m.cancel.set()
        m.thread.join(timeout=2.0)
        self._expect_ok("stop", self._transact("stop", self.cfg.command_timeout_s, self.cfg.command_retries))
        return True

    def _require_link(self, command: str) -> None:
        if not self._connected:
            raise LinkLost(f"robot {self.robot_id!r}: {command}: not connected (call connect() first)")
        if not self.link_ok:
            raise LinkLost(f"robot {self.robot_id!r}: {command}: link lost (no state packet for "
                           f"{self.cfg.state_timeout_s} s)")

    @property
    def busy(self) -> bool:
        """True while a manoeuvre (takeoff, go, land) is being executed."""
        m = self._motion
        return m is not None and m.thread is not None and m.thread.is_alive()

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

    # ------------------------------------------------------------------ control
    def arm(self) -> None:
        """The Tello has no arming step (``takeoff`` starts the motors): checks the link and the battery
        reported in the state packets, then marks the vehicle armed. Raises LinkLost / CommandRefused."""
        self._require_link("arm")
        if self._bat <= 10:
            raise CommandRefused(self.robot_id, "arm", "battery low", f"battery {self._bat:.0f} %")
        self._armed = True

    def disarm(self) -> None:
        """Marks the vehicle disarmed; refused while it is in the air (use :meth:`land` or :meth:`emergency`)."""
        if self.in_air:
            raise CommandRefused(self.robot_id, "disarm", "in air", f"height {self._h_cm:.0f} cm")
        self._armed = False

    def takeoff(self, altitude_m: float) -> None:
        """``takeoff`` (the Tello climbs to about 0.8 m), then ``up``/``down`` to ``altitude_m`` metres above the
        take-off point. Raises CommandRefused (the Tello's reply) or LinkLost; ValueError for a bad altitude."""
        if not (math.isfinite(altitude_m) and altitude_m > 0):
            raise ValueError(f"takeoff: altitude_m must be a positive number of metres, got {altitude_m!r}")
        c = self.cfg

        def plan(m: _Motion) -> None:
            if not self.in_air:
                self._retry_until(m, "takeoff", c.command_timeout_s + 3.0, lambda: self.in_air)
            self._armed = True
            self._climb_to(m, altitude_m)

        self._start_motion("takeoff", plan)

    def _climb_to(self, m: _Motion, altitude_m: float) -> None:
        for _ in range(int(altitude_m * 100) // GO_MAX_CM + 3):
            dz = int(round(altitude_m * 100 - self._h_cm))
            if abs(dz) < GO_MIN_CM:
                return
            step = min(abs(dz), GO_MAX_CM)
            word = "up" if dz > 0 else "down"
            self._motion_step(m, f"{word} {step}", self._motion_timeout(step / 100, self.limits.max_vertical_speed))

    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        """Fly to ``target_enu`` (ENU metres from home) with body-frame ``go x y z speed`` commands computed from
        the dead-reckoned position: legs longer than 5 m are cut into ``go`` chunks along the straight line; the
        remaining offset is recomputed after each one (so a lost reply is recovered without flying twice). When a
        ``go`` is answered ``ok``, the horizontal position is set to its start plus the commanded offset (the
        Tello's own estimate, finer than our integral of its 0.1 m/s state velocities).
        ``speed`` m/s (None: ``limits.max_speed``), clipped to the SDK's 0.1-1.0 m/s. Stops once every axis is
        within the 20 cm the ``go`` command cannot resolve. Raises CommandRefused / LinkLost / ValueError."""
        tgt = np.asarray([float(v) for v in target_enu], float)
        if tgt.shape != (3,) or not np.all(np.isfinite(tgt)):
            raise ValueError(f"goto: target_enu must be 3 finite ENU metres, got {target_enu!r}")
        v = self.limits.max_speed if speed is None else float(speed)
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"goto: speed must be a positive number of m/s, got {speed!r}")
        speed_cm = int(np.clip(round(v * 100), *GO_SPEED_CM))

        def plan(m: _Motion) -> None:
            unanswered = 0
            start = self.position
            max_legs = int(np.linalg.norm(tgt - start) * 100 // GO_MAX_CM) + 4
            for _ in range(max_legs):
                p0, yaw0 = self.position, math.radians(self.yaw)
                cmd = self._go_command(tgt, speed_cm)
                if cmd is None:
                    return
                fwd, left, up = (int(x) / 100.0 for x in cmd.split()[1:4])
                dist = math.sqrt(fwd * fwd + left * left + up * up)
                if self._motion_step(m, cmd, self._motion_timeout(dist, speed_cm / 100.0)) is not None:
                    # 'ok' = the Tello's own (optical-flow) estimate says it flew the commanded offset: trust it
                    # over our integral of velocities quantised to 0.1 m/s
                    with self._state_lock:
                        self._pos[0] = p0[0] + fwd * math.cos(yaw0) - left * math.sin(yaw0)
                        self._pos[1] = p0[1] + fwd * math.sin(yaw0) + left * math.cos(yaw0)
                else:
                    unanswered += 1
                    self.stats["retries"] += 1
                    if unanswered > self.cfg.command_retries:
                        raise BackendError(f"robot {self.robot_id!r}: {cmd}: no reply after "
                                           f"{unanswered} tries")
            if self._go_command(tgt, speed_cm) is not None:
                raise BackendError(f"robot {self.robot_id!r}: goto {tgt.round(2).tolist()}: still "
                                   f"{np.linalg.norm(tgt - self.position):.2f} m away after {max_legs} go commands")

        self._start_motion("goto", plan)

    def _go_command(self, tgt: np.ndarray, speed_cm: int) -> str | None:
        return go_command(tgt - self.position, self.yaw, speed_cm)

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        """``rc a b c d`` from the ENU velocity (m/s) rotated into the body frame with the current yaw: sticks
        are ``100 * v / limits.max_speed`` (right, forward), ``100 * v_up / limits.max_vertical_speed`` and
        ``-100 * yaw_rate / limits.max_yaw_rate`` (the Tello's yaw stick is clockwise-positive), clipped to
        -100..100. Stops a running manoeuvre first. Raises LinkLost / ValueError."""
        v = [float(c) for c in v_enu]
        if len(v) != 3 or not all(math.isfinite(c) for c in v) or not math.isfinite(yaw_rate_dps):
            raise ValueError(f"set_velocity: v_enu must be 3 finite m/s values and yaw_rate_dps finite, "
                             f"got {v_enu!r}, {yaw_rate_dps!r}")
        self._require_link("set_velocity")
        self._preempt()
        yaw = math.radians(self.yaw)
        fwd = v[0] * math.cos(yaw) + v[1] * math.sin(yaw)
        right = v[0] * math.sin(yaw) - v[1] * math.cos(yaw)
        lim = self.limits

        def stick(x: float, full: float) -> int:
            return int(np.clip(round(100.0 * x / full), -100, 100))

        self._sticks = (stick(right, lim.max_speed), stick(fwd, lim.max_speed),
                        stick(v[2], lim.max_vertical_speed), stick(-yaw_rate_dps, lim.max_yaw_rate))
        self._send_rc(self._sticks)

    def hold(self) -> None:
        """Hover: ``stop`` when a manoeuvre is running, else ``rc 0 0 0 0``. Raises LinkLost when the link is
        down (after still sending the command)."""
        self._sticks = (0, 0, 0, 0)
        if self.busy:
            self._preempt()
        else:
            self._send_rc(self._sticks)
        if not self.link_ok:
            raise LinkLost(f"robot {self.robot_id!r}: hold: link lost (no state packet for "
                           f"{self.cfg.state_timeout_s} s)")

    def land(self) -> None:
        """``land`` where the vehicle is (re-sent only while the state still shows it in the air).
        Raises CommandRefused / LinkLost."""
        self._sticks = (0, 0, 0, 0)

        def plan(m: _Motion) -> None:
            self._retry_until(m, "land", self._motion_timeout(self._h_cm / 100.0, 0.5), lambda: not self.in_air)
            self._armed = False

        self._start_motion("land", plan)

    def emergency(self) -> None:
        """``emergency``: stop the motors at once (the Tello falls). Sent without waiting for a manoeuvre."""
        m = self._motion
        if m is not None:
            m.cancel.set()
        self._send("emergency")
        self._armed = False
