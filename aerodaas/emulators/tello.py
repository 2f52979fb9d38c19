"""A DJI Tello emulator on loopback UDP, written from the *Tello SDK 2.0 User Guide* (Ryze Tech, 2018-11).

It answers SDK text commands on its command port, sends state packets at ``state_hz`` to the client's state
port, and, after ``streamon``, an H.264 stream rendered from the simulated world to the client's video port, the
way a Tello does (see :mod:`aerodaas.backends.tello` for the protocol). The flight model is
:class:`aerodaas.sim.vehicle.SimVehicle` stepped in real time; the camera is :class:`aerodaas.sim.world.World`
(procedural ground) looking forward, ``camera_pitch_deg`` below the horizon, encoded with libx264 through PyAV.

Emulated behaviour:

* replies: ``ok`` / ``error ...`` / ``out of range`` / ``unknown command: X``; motion commands (``takeoff``,
  ``land``, ``go``, ``up``/``down``/``forward``/``back``/``left``/``right``, ``cw``/``ccw``) answer when finished;
  other commands while one runs get ``error Not joystick``; ``stop`` (hover) and ``emergency`` work at any time and
  end the running one without a reply; ``rc`` is never answered and ignored while a manoeuvre runs; nothing is
  answered before ``command``.
* state: ``pitch;roll;yaw;vgx;vgy;vgz;templ;temph;tof;h;bat;baro;time;agx;agy;agz`` (with ``mid;x;y;z;mpry``
  in front when ``mission_pad_fields``); yaw clockwise-positive relative to the power-on heading
  ``initial_heading_deg``; velocities in dm/s in the frame ``velocity_frame`` (see
  :class:`aerodaas.config.TelloConfig`).
* safety: it lands by itself ``auto_land_s`` seconds (15 on a real Tello) after the last datagram received or the
  last manoeuvre finished, whichever is later.
* faults for tests: :meth:`drop_next_reply`, :meth:`send_raw_state`, :attr:`state_paused`, ``refuse`` (a reply
  such as ``error`` to a command word instead of carrying it out, e.g. ``{"streamon": "error"}``).

Not emulated: flips, curves, mission pads, Wi-Fi settings, the Tello's own velocity/position estimation errors,
wind, video bit-rate adaptation, packet loss (except injected faults), low-battery auto-landing.
"""
from __future__ import annotations

import math
import socket
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Callable

import numpy as np

from aerodaas.config import BatteryConfig, GroundConfig, Limits
from aerodaas.model.types import CameraIntrinsics, FramePose, GeoPoint
from aerodaas.sim.vehicle import Setpoint, SimVehicle
from aerodaas.sim.world import CAMERA_MIN_HEIGHT_M, World

__all__ = ["TelloEmulator", "format_state", "stamp_index", "read_index"]

DATAGRAM_SIZE = 1460
#: a Tello battery: 1.1 Ah x 3.8 V; ~13 min hover at 19 W
TELLO_BATTERY = BatteryConfig(capacity_wh=4.18, hover_power_w=19.0, speed_power_w_per_mps=2.0,
                              voltage_full=4.35, voltage_empty=3.5)
TELLO_LIMITS = Limits(max_speed=1.0, max_vertical_speed=1.0, max_acceleration=3.0, max_yaw_rate=100.0,
                      max_altitude=30.0)


def format_state(*, pitch: float, roll: float, yaw: float, vgx: float, vgy: float, vgz: float, h_cm: float,
                 bat: float, baro_m: float, motor_s: float, agx: float = 0.0, agy: float = 0.0,
                 agz: float = -1000.0, templ: int = 60, temph: int = 63, mission_pad_fields: bool = False) -> bytes:
    """One state datagram in the SDK 2.0 format (integers where the guide says ``%d``)."""
    pad = "mid:-2;x:-200;y:-200;z:-200;mpry:0,0,0;" if mission_pad_fields else ""
    text = (f"{pad}pitch:{int(round(pitch))};roll:{int(round(roll))};yaw:{int(round(yaw))};"
            f"vgx:{int(round(vgx))};vgy:{int(round(vgy))};vgz:{int(round(vgz))};templ:{templ};temph:{temph};"
            f"tof:{int(round(h_cm)) + 10};h:{int(round(h_cm))};bat:{int(bat)};baro:{baro_m:.2f};"
            f"time:{int(motor_s)};agx:{agx:.2f};agy:{agy:.2f};agz:{agz:.2f};\r\n")
    return text.encode("ascii")


@dataclass
class _Manoeuvre:
    name: str
    addr: tuple[str, int]
    done: Callable[[], bool]


class TelloEmulator:
    """An emulated Tello on ``host`` (default loopback). Use as a context manager or :meth:`start`/:meth:`stop`.

    Ports: commands on ``command_port`` (0: a free port, see :attr:`command_port`); state and video go to the
    client's address (the sender of ``command``) on ``state_port`` and ``video_port``. ``limits`` set the flight
    envelope (``rc`` full stick = ``max_speed``/``max_vertical_speed``/``max_yaw_rate``); ``go`` speeds are the
    SDK's 10-100 cm/s. Video: ``video_size`` (width, height) px at ``video_fps``, horizontal field of view
    ``hfov_deg``; ``stamp_frame_index`` writes each frame's index as a 16-bit barcode in the top 8 rows (for
    latency measurements). Everything it rendered and sent recently is in :attr:`sent_frames`
    (``(monotonic send time, index, (H, W, 3) uint8 BGR frame)``). The take-off point (the vehicle's ENU origin,
    :attr:`position`) lies at ``start_enu`` metres in the rendered world (off the procedural ground's tracks).
    ``refuse``: command word -> the reply sent instead of carrying the command out (see :attr:`refusals`)."""

    def __init__(self, *, host: str = "127.0.0.1", command_port: int = 0, state_port: int = 8890,
                 video_port: int = 11111, state_hz: float = 10.0, auto_land_s: float = 15.0,
                 initial_heading_deg: float = 0.0, limits: Limits | None = None, battery_pct: float = 90.0,
                 takeoff_height_m: float = 0.8, physics_hz: float = 50.0, velocity_frame: str = "yaw_zero",
                 mission_pad_fields: bool = False, video_fps: float = 30.0, video_size: tuple[int, int] = (960, 720),
                 hfov_deg: float = 82.6, camera_pitch_deg: float = 10.0, ground: GroundConfig | None = None,
                 bitrate: int | None = None, stamp_frame_index: bool = False,
                 home: GeoPoint | None = None, start_enu: tuple[float, float] = (5.0, 5.0),
                 refuse: dict[str, str] | None = None) -> None:
        if velocity_frame not in ("yaw_zero", "body"):
            raise ValueError(f"velocity_frame must be 'yaw_zero' or 'body', got {velocity_frame!r}")
        self.host = host
        self.state_port, self.video_port = int(state_port), int(video_port)
        self.state_hz, self.auto_land_s, self.physics_hz = float(state_hz), float(auto_land_s), float(physics_hz)
        self.initial_heading_deg = float(initial_heading_deg)
        self.limits = limits or TELLO_LIMITS
        self.takeoff_height_m = float(takeoff_height_m)
        self.velocity_frame, self.mission_pad_fields = velocity_frame, mission_pad_fields
        self.video_fps, self.video_size, self.hfov_deg = float(video_fps), tuple(video_size), float(hfov_deg)
        self.camera_pitch_deg = float(camera_pitch_deg)
        self.ground = ground or GroundConfig(size_m=60.0, seed=7)
        w, h = self.video_size
        self.bitrate = int(bitrate or max(300_000, 0.1 * w * h * self.video_fps))
        self.stamp_frame_index = stamp_frame_index
        self.start_enu = (float(start_enu[0]), float(start_enu[1]))
        self.home = home or GeoPoint(lat=47.3977, lon=8.5456, alt=488.0)
        battery = TELLO_BATTERY.model_copy(update={"initial_pct": float(battery_pct)})
        self.vehicle = SimVehicle("tello-emulator", self.home, self.limits, battery)
        self.vehicle.state.yaw = (90.0 - self.initial_heading_deg) % 360.0  # faces its power-on heading
        self._lock = threading.RLock()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((host, int(command_port)))
        self._sock.settimeout(0.1)
        self._out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._client: str | None = None
        self._sdk_mode = False
        self._streaming = False
        self._manoeuvre: _Manoeuvre | None = None
        self._yaw_target: float | None = None
        self._sticks = (0, 0, 0, 0)
        self._speed_cms = 100
        self._last_rx = time.monotonic()
        self._motor_s = 0.0
        self._drop: dict[str, int] = {}
        self._prev_v_body = np.zeros(3)
        self.state_paused = False
        #: command word -> reply sent instead of carrying the command out (e.g. ``{"streamon": "error"}``)
        self.refusals: dict[str, str] = dict(refuse or {})
        #: every datagram received: (monotonic time, text)
        self.received: list[tuple[float, str]] = []
        self.auto_landings = 0
        self.dropped_replies = 0
        self._world: World | None = None  # built on first use (a second or so for the procedural ground)
        self._world_lock = threading.Lock()
        self.sent_frames: deque[tuple[float, int, np.ndarray]] = deque(maxlen=64)
        #: frame index -> monotonic time its first datagram was sent (the last 100 000 frames)
        self.send_times: dict[int, float] = {}
        self.frames_sent = 0
        self.datagrams_sent = 0

    # ------------------------------------------------------------------ lifecycle
    @property
    def command_port(self) -> int:
        """The UDP port commands are received on."""
        return self._sock.getsockname()[1]

    def start(self) -> "TelloEmulator":
        for fn, name in ((self._command_loop, "cmd"), (self._physics_loop, "physics"), (self._video_loop, "video")):
            th = threading.Thread(target=fn, name=f"tello-emu-{name}", daemon=True)
            th.start()
            self._threads.append(th)
        return self

    def stop(self) -> None:
        self._stop.set()
        for th in self._threads:
            th.join(timeout=3.0)
        self._sock.close()
        self._out.close()

    def __enter__(self) -> "TelloEmulator":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ faults
    def drop_next_reply(self, command_word: str, n: int = 1) -> None:
        """Do not send the next ``n`` replies to commands starting with ``command_word`` (a lost datagram)."""
        with self._lock:
            self._drop[command_word] = self._drop.get(command_word, 0) + n

    def send_raw_state(self, data: bytes) -> None:
        """Send ``data`` to the client's state port as if it were a state packet."""
        if self._client is not None:
            self._out.sendto(data, (self._client, self.state_port))

    # ------------------------------------------------------------------ ground truth for tests
    @property
    def in_air(self) -> bool:
        return self.vehicle.state.in_air

    @property
    def position(self) -> np.ndarray:
        with self._lock:
            return self.vehicle.state.position.copy()

    @property
    def yaw_enu(self) -> float:
        return float(self.vehicle.state.yaw)

    @property
    def busy(self) -> bool:
        return self._manoeuvre is not None

    def tello_yaw(self) -> float:
        """The yaw a Tello reports: degrees clockwise from its power-on heading, in [-180, 180)."""
        heading = 90.0 - self.vehicle.state.yaw
        return (heading - self.initial_heading_deg + 180.0) % 360.0 - 180.0

    # ------------------------------------------------------------------ commands
    def _reply(self, text: str, addr: tuple[str, int], word: str) -> None:
        with self._lock:
            if self._drop.get(word, 0) > 0:
                self._drop[word] -= 1
                self.dropped_replies += 1
                return
        self._sock.sendto(text.encode("utf-8"), addr)

    def _command_loop(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self._sock.recvfrom(2048)
            except socket.timeout:
                continue
            except OSError:
                return
            text = data.decode("utf-8", "replace").strip()
            now = time.monotonic()
            with self._lock:
                self.received.append((now, text))
                self._last_rx = now
                if text == "command":
                    self._sdk_mode, self._client = True, addr[0]
                if not self._sdk_mode:
                    continue
                word = text.split(" ", 1)[0]
                reply = self._handle(text, addr)
            if reply is not None:
                self._reply(reply, addr, word)

    def _handle(self, text: str, addr: tuple[str, int]) -> str | None:
        """The immediate reply to ``text``, or None (no reply now: rc, or a manoeuvre that replies when done)."""
        parts = text.split()
        word, args = parts[0], parts[1:]
        v = self.vehicle
        flying = v.state.in_air
        if word == "command":
            return "ok"
        if word in self.refusals:
            return self.refusals[word]
        if word == "rc":
            self._rc(args)
            return None
        if word == "stop":
            self._manoeuvre, self._yaw_target = None, None
            self._sticks = (0, 0, 0, 0)
            if flying:
                v.hold()
            return "ok"
        if word == "emergency":
            self._manoeuvre, self._yaw_target = None, None
            s = v.state
            s.in_air, s.armed = False, False
            s.position[2], s.velocity[:] = 0.0, 0.0
            v.setpoint = Setpoint("idle")
            return "ok"
        reads = {"battery?": lambda: str(int(v.battery_pct)), "speed?": lambda: f"{float(self._speed_cms):.1f}",
                 "time?": lambda: f"{int(self._motor_s)}s", "height?": lambda: f"{int(v.state.position[2] * 10)}dm",
                 "wifi?": lambda: "90", "sdk?": lambda: "20"}
        if word in reads and not args:
            return reads[word]()
        if word in ("streamon", "streamoff"):
            self._streaming = word == "streamon"
            return "ok"
        if word == "speed":
            n = self._ints(args, 1)
            if n is None or not 10 <= n[0] <= 100:
                return "out of range"
            self._speed_cms = n[0]
            return "ok"
        motions = ("takeoff", "land", "go", "up", "down", "forward", "back", "left", "right", "cw", "ccw")
        if word not in motions:
            return f"unknown command: {text}"
        if self._manoeuvre is not None:
            return "error Not joystick"
        return self._motion(word, args, addr)

    def _motion(self, word: str, args: list[str], addr: tuple[str, int]) -> str | None:
        """A manoeuvre command (SDK 2.0: takeoff, land, go, up/down/forward/back/left/right in cm, cw/ccw in
        degrees): its error reply, or None (the reply comes when it is done)."""
        v = self.vehicle
        flying = v.state.in_air
        if word == "takeoff":
            if flying:
                return "error"
            if v.battery_pct < 10:
                return "error No valid battery"
            v.arm()
            v.takeoff(self.takeoff_height_m)
            return self._begin("takeoff", addr, lambda: v.state.position[2] >= self.takeoff_height_m - 0.02)
        if not flying:
            return "error Motor stop"
        if word == "land":
            v.land()
            self._sticks = (0, 0, 0, 0)
            return self._begin("land", addr, lambda: not v.state.in_air)
        if word in ("cw", "ccw"):
            n = self._ints(args, 1)
            if n is None or not 1 <= n[0] <= 360:
                return "out of range"
            v.hold()
            self._yaw_target = v.state.yaw + (-n[0] if word == "cw" else n[0])
            return self._begin(word, addr, lambda: self._yaw_target is None)
        return self._move(word, args, addr)

    def _move(self, word: str, args: list[str], addr: tuple[str, int]) -> str | None:
        """go x y z speed (cm, cm/s, body frame) or a straight move of n cm: a goto to the target in the world."""
        v = self.vehicle
        if word == "go":
            n = self._ints(args, 4)
            if (n is None or not all(-500 <= c <= 500 for c in n[:3]) or not 10 <= n[3] <= 100
                    or all(-20 <= c <= 20 for c in n[:3])):
                return "out of range"
            body, speed = n[:3], n[3]
        else:
            n = self._ints(args, 1)
            if n is None or not 20 <= n[0] <= 500:
                return "out of range"
            unit = {"up": (0, 0, 1), "down": (0, 0, -1), "forward": (1, 0, 0), "back": (-1, 0, 0),
                    "left": (0, 1, 0), "right": (0, -1, 0)}[word]
            body, speed = [n[0] * u for u in unit], self._speed_cms
        yaw = math.radians(v.state.yaw)
        fx, ly, uz = (c / 100.0 for c in body)
        target = v.state.position + np.array([fx * math.cos(yaw) - ly * math.sin(yaw),
                                              fx * math.sin(yaw) + ly * math.cos(yaw), uz])
        target[2] = min(max(target[2], 0.2), self.limits.max_altitude)
        v.goto(tuple(target), speed / 100.0)
        return self._begin(word, addr, lambda: (np.linalg.norm(v.state.position - target) < 0.02
                                                and np.linalg.norm(v.state.velocity) < 0.05))

    def _begin(self, name: str, addr: tuple[str, int], done: Callable[[], bool]) -> None:
        self._manoeuvre = _Manoeuvre(name, addr, done)
        self._sticks = (0, 0, 0, 0)
        return None

    @staticmethod
    def _ints(args: list[str], n: int) -> list[int] | None:
        if len(args) != n:
            return None
        try:
            return [int(a) for a in args]
        except ValueError:
            return None

    def _rc(self, args: list[str]) -> None:
        n = self._ints(args, 4)
        if n is None or not all(-100 <= c <= 100 for c in n) or self._manoeuvre is not None:
            return
        self._sticks = tuple(n)
        if self.vehicle.state.in_air and not any(n):
            self.vehicle.hold()

    # ------------------------------------------------------------------ physics, state, auto-land
    def _physics_loop(self) -> None:
        dt_phys = 1.0 / self.physics_hz
        next_state = time.monotonic()
        last = time.monotonic()
        while not self._stop.wait(dt_phys):
            now = time.monotonic()
            dt = min(now - last, 0.1)
            last = now
            with self._lock:
                self._step(dt, now)
                state = self._state_packet(dt) if now >= next_state else None
            if state is not None:
                next_state = now + 1.0 / self.state_hz
                if self._client is not None and not self.state_paused:
                    try:
                        self._out.sendto(state, (self._client, self.state_port))
                    except OSError:
                        pass

    def _step(self, dt: float, now: float) -> None:
        v, s, lim = self.vehicle, self.vehicle.state, self.limits
        a, b, c, d = self._sticks
        if self._manoeuvre is None and s.in_air and any(self._sticks):
            yaw = math.radians(s.yaw)
            right, fwd = a / 100.0 * lim.max_speed, b / 100.0 * lim.max_speed
            v.set_velocity((fwd * math.cos(yaw) + right * math.sin(yaw), fwd * math.sin(yaw) - right * math.cos(yaw),
                            c / 100.0 * lim.max_vertical_speed), -d / 100.0 * lim.max_yaw_rate)
        if self._yaw_target is not None:
            err = self._yaw_target - s.yaw
            stepmax = lim.max_yaw_rate * dt
            if abs(err) <= stepmax:
                s.yaw, self._yaw_target = self._yaw_target % 360.0, None
            else:
                s.yaw += math.copysign(stepmax, err)
        v.step(dt)
        if s.in_air:
            self._motor_s += dt
        m = self._manoeuvre
        if m is not None and m.done():
            self._manoeuvre = None
            self._last_rx = max(self._last_rx, now)  # the 15 s count starts when a command is finished
            if m.name == "land":
                v.disarm()
            elif s.in_air and m.name != "cw" and m.name != "ccw":
                v.hold()
            self._reply("ok", m.addr, m.name)
        if (s.in_air and self._manoeuvre is None and self.auto_land_s > 0
                and now - self._last_rx > self.auto_land_s and v.setpoint.mode != "land"):
            self.auto_landings += 1
            self._sticks = (0, 0, 0, 0)
            v.land()

    def _state_packet(self, dt: float) -> bytes:
        s, v = self.vehicle.state, self.vehicle
        yaw_t = self.tello_yaw()
        h0 = math.radians(self.initial_heading_deg if self.velocity_frame == "yaw_zero" else 90.0 - s.yaw)
        east, north, up = s.velocity
        vx = north * math.cos(h0) + east * math.sin(h0)
        vy = -north * math.sin(h0) + east * math.cos(h0)
        vbody = np.array([vx, vy, -up])
        acc = (vbody - self._prev_v_body) / max(1.0 / self.state_hz, dt) / 9.81 * 1000.0
        self._prev_v_body = vbody
        odo = v.odometry()
        return format_state(pitch=odo.attitude.pitch, roll=0.0, yaw=yaw_t, vgx=vx * 10, vgy=vy * 10, vgz=-up * 10,
                            h_cm=s.position[2] * 100.0, bat=v.battery_pct, baro_m=self.home.alt + s.position[2],
                            motor_s=self._motor_s, agx=acc[0], agy=acc[1], agz=acc[2] - 1000.0,
                            mission_pad_fields=self.mission_pad_fields)

    # ------------------------------------------------------------------ video
    def render(self, position: tuple[float, float, float], yaw_enu: float) -> np.ndarray:
        """What the emulated camera sees from ``position`` (ENU m from the take-off point) with ``yaw_enu`` (deg):
        (H, W, 3) uint8 BGR."""
        z = max(float(position[2]), CAMERA_MIN_HEIGHT_M)
        x, y = float(position[0]) + self.start_enu[0], float(position[1]) + self.start_enu[1]
        pose = FramePose(position=(x, y, z), yaw=float(yaw_enu),
                         camera_pitch=self.camera_pitch_deg)
        with self._world_lock:
            if self._world is None:
                self._world = World(self.ground, [])
        w, h = self.video_size
        return self._world.render(pose, CameraIntrinsics.from_hfov(w, h, self.hfov_deg), 0.0)[0]

    def _video_loop(self) -> None:
        import av  # lazy: only a streaming emulator needs PyAV

        enc = None
        period = 1.0 / self.video_fps
        next_t = time.monotonic()
        while not self._stop.is_set():
            if not (self._streaming and self._client is not None):
                enc = None  # a new stream starts with a key frame and its parameter sets
                self._stop.wait(0.02)
                next_t = time.monotonic()
                continue
            if enc is None:
                enc = self._encoder(av)
            with self._lock:
                pos, yaw = tuple(self.vehicle.state.position), self.vehicle.state.yaw
            frame = self.render(pos, yaw)
            idx = self.frames_sent
            if self.stamp_frame_index:
                stamp_index(frame, idx)
            vf = av.VideoFrame.from_ndarray(frame, format="bgr24")
            vf.pts = idx
            data = b"".join(bytes(p) for p in enc.encode(vf))
            t_send = time.monotonic()
            for i in range(0, len(data), DATAGRAM_SIZE):
                try:
                    self._out.sendto(data[i:i + DATAGRAM_SIZE], (self._client, self.video_port))
                except OSError:
                    break
                self.datagrams_sent += 1
            if data and len(data) % DATAGRAM_SIZE == 0:  # keep the "short datagram ends a frame" rule
                self._out.sendto(b"\x00\x00\x01\x09\xf0", (self._client, self.video_port))  # access unit delimiter
            self.sent_frames.append((t_send, idx, frame))
            self.send_times[idx] = t_send
            self.send_times.pop(idx - 100_000, None)
            self.frames_sent += 1
            next_t += period
            delay = next_t - time.monotonic()
            if delay < -period:
                next_t = time.monotonic()
            self._stop.wait(max(delay, 0.0))

    def _encoder(self, av):
        name = "libx264" if "libx264" in av.codecs_available else "h264"
        enc = av.CodecContext.create(name, "w")
        enc.width, enc.height = self.video_size
        enc.pix_fmt = "yuv420p"
        enc.framerate = int(round(self.video_fps))
        enc.bit_rate = self.bitrate
        enc.gop_size = max(1, int(round(self.video_fps)))
        if name == "libx264":
            enc.options = {"preset": "ultrafast", "tune": "zerolatency", "repeat-headers": "1"}
        return enc


def stamp_index(frame: np.ndarray, idx: int, bits: int = 16) -> None:
    """Write ``idx`` as a ``bits``-bit barcode into the top 8 rows of ``frame`` (in place): block ``i`` of width
    ``W // bits`` is white for a 1 bit. :func:`read_index` reads it back from a decoded frame."""
    w = frame.shape[1] // bits
    for i in range(bits):
        frame[:8, i * w:(i + 1) * w] = 255 if (idx >> i) & 1 else 0


def read_index(frame: np.ndarray, bits: int = 16) -> int:
    """The index :func:`stamp_index` wrote (robust to compression: each block's mean against mid-grey)."""
    w = frame.shape[1] // bits
    return sum(1 << i for i in range(bits) if frame[1:7, i * w + 2:(i + 1) * w - 2].mean() > 127)
