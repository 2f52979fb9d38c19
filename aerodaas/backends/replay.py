"""Replay of recorded flights: a MAVLink telemetry log as a (non-navigable) vehicle, and an MCAP recording's camera
channel as a frame source, so that analytics and their schedulers can be re-run on a real or recorded flight.

:class:`ReplayBackend` plays a ``.tlog`` (pymavlink's reader; the format is each MAVLink packet prefixed by its
capture time, a big-endian uint64 of microseconds) at ``rate`` x real time:

* odometry from ``GLOBAL_POSITION_INT`` (lat/lon -> ENU about home with pymap3d, ``relative_alt`` as height above
  home, NED velocity -> ENU) and ``ATTITUDE`` (roll, pitch, yaw -> ENU yaw);
* battery from ``BATTERY_STATUS.battery_remaining`` (``SYS_STATUS`` when the log has no BATTERY_STATUS), voltage
  from ``SYS_STATUS.voltage_battery``;
* armed and flight mode from the vehicle's ``HEARTBEAT`` (``base_mode`` bit ``MAV_MODE_FLAG_SAFETY_ARMED``;
  PX4/ArduPilot custom modes decoded by ``pymavlink.mavutil.mode_string_v10``), in-air from
  ``EXTENDED_SYS_STATE.landed_state``;
* home from the first ``HOME_POSITION`` (else the first ``GLOBAL_POSITION_INT`` with a fix), updated when a later
  HOME_POSITION moves it.

A PX4 flight log (``.ulg``, read with pyulog) plays the same way: its uORB topics are turned into the MAVLink
messages above, in MAVLink units, by :func:`load_ulog` (see there). A ULog has no radio link, so link loss is never
reported for it.

Only the vehicle's own messages count, and a packet a router forwarded on two links is played once: the logs are
read by :mod:`aerodaas.backends.flight_log` (see there).

A battery reported as unknown (``battery_remaining`` -1, MAVLink's "not available") stays unknown: ``battery_pct``
is None and the odometry records ``null``, never 100 %.
"""
from __future__ import annotations

import bisect
import math
import os
import time
from pathlib import Path
from typing import Any, Iterator, NoReturn, Sequence

import numpy as np

from aerodaas.config.base import ConfigError
from aerodaas.model.geo import geodetic_to_enu
from aerodaas.model.types import Attitude, GeoPoint, Odometry
from aerodaas.backends.base import BackendError, NotNavigable, StateSamples, VehicleBackend, VehicleState
from aerodaas.backends.flight_log import MAV_MODE_FLAG_SAFETY_ARMED, LogMessage, check_log, load_tlog, load_ulog
from aerodaas.config.backends import ReplayConfig

__all__ = ["ReplayBackend", "NoCommands", "McapCameraReplay"]

#: the link counts as lost after this many seconds of log time without a vehicle HEARTBEAT (as a GCS would)
HEARTBEAT_TIMEOUT_S = 3.0
_MAV_LANDED_STATE_IN_AIR = (2, 3, 4)  # IN_AIR, TAKEOFF, LANDING


def _home_of(m: Any) -> GeoPoint | None:
    """Home from a HOME_POSITION (or a GLOBAL_POSITION_INT with a fix); None without one."""
    if m.get_type() == "HOME_POSITION":
        return GeoPoint(lat=m.latitude / 1e7, lon=m.longitude / 1e7, alt=m.altitude / 1000.0)
    if m.lat == 0 and m.lon == 0:
        return None
    return GeoPoint(lat=m.lat / 1e7, lon=m.lon / 1e7, alt=(m.alt - m.relative_alt) / 1000.0)


class ReplayBackend(VehicleBackend):
    """A recorded flight played back as a vehicle that reports but cannot be commanded (see the module docstring).

    Clock ``"vehicle"``: :attr:`t` is log time (seconds since the log's first record) = ``rate`` x wall seconds
    since the first :meth:`step` (0 until then); :meth:`step` applies every message up to :attr:`t` and never
    blocks. Odometry's ``t`` is the log time up to which messages have been applied. Events (:meth:`drain_events`, each with its log time
    ``t``): ``mode`` (name), ``armed``, ``disarmed``, ``status_text`` (severity, text),
    ``mission_item_reached`` (seq; PX4 repeats the message for about a second, reported once per item),
    ``home`` (lat, lon, alt), ``link_lost``/``link_regained`` (gaps of HEARTBEAT_TIMEOUT_S in the log's
    heartbeats), and ``replay_finished`` after the last message (then :attr:`finished` is True).

    Every command (:attr:`actions`, :attr:`guidance`: :class:`NoCommands`) raises
    :class:`~aerodaas.backends.base.NotNavigable`.
    """

    kind = "replay"
    clock = "vehicle"
    navigable = False
    Config = ReplayConfig
    config_section = "replay"

    @classmethod
    def resolve_files(cls, robot: Any, resolve: Any, where: str) -> None:
        """The log (``replay.log``), resolved like every file of the environment and checked to hold a flight
        (:func:`check_log`): a missing or empty log fails before Ray starts. Raises ConfigError naming the field."""
        field = f"{where}.{cls.config_section}.log"
        robot.backend_config["log"] = log = str(resolve(cls.options(robot).log, field))
        try:
            check_log(log)
        except BackendError as e:
            raise ConfigError(f"{field}: {e}") from None

    @classmethod
    def clock_rate(cls, robot: Any) -> float | None:
        """``replay.rate``: log seconds per wall second."""
        return float(cls.options(robot).rate)

    def __init__(self, cfg) -> None:  # cfg: aerodaas.config.RobotConfig (settings: ReplayConfig)
        super().__init__(cfg.id, cfg.home)
        #: a recording cannot be flown: every command raises NotNavigable
        self.actions = self.guidance = NoCommands(self.robot_id, self.kind)
        #: the position samples: the log's own fix and battery voltage, at the log time applied so far
        self.telemetry = StateSamples(self, odometry=self._odometry)
        settings = self.options(cfg)
        self.log_path = str(settings.log)
        self.rate = float(settings.rate)
        self.info: dict[str, Any] = {}
        self._msgs: list[LogMessage] = []
        self._i = 0
        self._t_wall0: float | None = None
        self._t_applied = 0.0
        self._pos = np.zeros(3)
        self._vel = np.zeros(3)
        self._att = Attitude()
        self._geo: GeoPoint | None = None
        self._bat: float | None = None  # unknown until the log reports it (battery_remaining -1 = unknown)
        self._volt = 0.0
        self._have_battery_status = False
        self._armed = False
        self._landed_state: int | None = None
        self._mode = ""
        self._last_reached: int | None = None
        self._last_hb: float | None = None
        self._link_ok = True
        self.finished = False
        self._link_monitor = True
        self._events: list[dict[str, Any]] = []
        self._clock_started = False  # the replay clock runs from the first step (see connect)

    # ------------------------------------------------------------------ lifecycle
    def connect(self, timeout_s: float = 30.0) -> None:
        """Read the log (``.tlog`` or PX4 ``.ulg``) and start the replay clock. Raises BackendError for a missing, unreadable or
        unsupported log (the message names ``replay.log`` and the path)."""
        suffix = Path(self.log_path).suffix.lower()
        if not Path(self.log_path).is_file():
            raise BackendError(f"robot {self.robot_id!r}: replay.log {self.log_path!r}: file not found")
        if suffix == ".ulg":
            self._msgs, self.info = load_ulog(self.log_path)
            self._link_monitor = False  # an onboard log has no radio link to lose
        else:
            self._msgs, self.info = load_tlog(self.log_path)
        self.info["duration_s"] = self._msgs[-1].t if self._msgs else 0.0
        home = next((h for lm in self._msgs if lm.type == "HOME_POSITION" for h in [_home_of(lm.msg)] if h), None)
        home = home or next((h for lm in self._msgs if lm.type == "GLOBAL_POSITION_INT"
                             for h in [_home_of(lm.msg)] if h), None)
        if home is not None:
            self.home = home
        # the replay clock starts at the first step of the flight, not here: the actors still set up after connect
        # (a second on a loaded machine, a minute of a 60x replay's log)
        self._t_wall0 = None
        self._clock_started = False

    def close(self) -> None:
        self._t_wall0 = None
        self._clock_started = True  # stopped for good: a later step does not start it again

    @property
    def duration_s(self) -> float:
        """Log time of the last vehicle message, seconds."""
        return float(self.info.get("duration_s", 0.0))

    # ------------------------------------------------------------------ time and state
    def _log_now(self) -> float:
        """Log time now: ``rate`` x wall seconds since the first :meth:`step` (the applied time before it and after
        :meth:`close`)."""
        if self._t_wall0 is None:
            return self._t_applied
        return (time.monotonic() - self._t_wall0) * self.rate

    def step(self, dt: float) -> None:
        """Apply every log message with log time <= :attr:`t` (``dt`` is ignored: the log has its own clock, started
        by the first call)."""
        if not self._clock_started:
            self._clock_started = True
            self._t_wall0 = time.monotonic() - self._t_applied / self.rate
        now = self._log_now()
        msgs = self._msgs
        while self._i < len(msgs) and msgs[self._i].t <= now:
            lm = msgs[self._i]
            self._i += 1
            self._apply(lm)
        self._t_applied = now
        if self._link_monitor and not self.finished and self._last_hb is not None:
            ok = now - self._last_hb < HEARTBEAT_TIMEOUT_S
            if ok != self._link_ok and self._i < len(msgs):
                self._link_ok = ok
                self._event("link_regained" if ok else "link_lost", now)
        if self._i >= len(msgs) and not self.finished:
            self.finished = True
            self._event("replay_finished", now, messages=len(msgs))

    def _apply(self, lm: LogMessage) -> None:
        m, t = lm.msg, lm.t
        ty = lm.type
        if ty == "GLOBAL_POSITION_INT":
            if m.lat == 0 and m.lon == 0:
                return
            e, n, _ = geodetic_to_enu(m.lat / 1e7, m.lon / 1e7, m.alt / 1000.0, self.home)
            self._pos = np.array([e, n, m.relative_alt / 1000.0])
            self._vel = self.ned_to_enu((m.vx / 100.0, m.vy / 100.0, m.vz / 100.0))
            self._geo = GeoPoint(lat=m.lat / 1e7, lon=m.lon / 1e7, alt=m.alt / 1000.0)
        elif ty == "ATTITUDE":
            self._att = Attitude(roll=math.degrees(m.roll), pitch=math.degrees(m.pitch),
                                 yaw=self.enu_yaw_from_heading(math.degrees(m.yaw)))
        elif ty == "BATTERY_STATUS":
            if m.battery_remaining >= 0:
                self._bat, self._have_battery_status = float(m.battery_remaining), True
        elif ty == "SYS_STATUS":
            if m.voltage_battery not in (0, 65535):
                self._volt = m.voltage_battery / 1000.0
            if not self._have_battery_status and m.battery_remaining >= 0:
                self._bat = float(m.battery_remaining)
        elif ty == "HEARTBEAT":
            self._heartbeat(m, t)
        elif ty == "EXTENDED_SYS_STATE":
            self._landed_state = int(m.landed_state)
        elif ty == "HOME_POSITION":
            home = _home_of(m)
            if home is not None and (home.lat, home.lon, home.alt) != (self.home.lat, self.home.lon, self.home.alt):
                self.home = home
                self._event("home", t, lat=home.lat, lon=home.lon, alt=home.alt)
        elif ty == "STATUSTEXT":
            text = m.text if isinstance(m.text, str) else bytes(m.text).decode("utf-8", "replace")
            self._event("status_text", t, severity=int(m.severity), text=text.rstrip("\x00").strip())
        elif ty == "MISSION_ITEM_REACHED":
            if m.seq != self._last_reached:
                self._last_reached = int(m.seq)
                self._event("mission_item_reached", t, seq=int(m.seq))

    def _heartbeat(self, m: Any, t: float) -> None:
        from pymavlink import mavutil  # lazy: heavy pymavlink

        self._last_hb = t
        armed = bool(m.base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
        if armed != self._armed:
            self._armed = armed
            self._event("armed" if armed else "disarmed", t)
        mode = getattr(m, "mode_name", None) or mavutil.mode_string_v10(m)
        if mode != self._mode:
            self._mode = mode
            self._event("mode", t, name=mode)

    def _event(self, kind: str, t: float, **kw: Any) -> None:
        self._events.append({"event": kind, "t": t, **kw})

    def drain_events(self) -> list[dict[str, Any]]:
        out, self._events = self._events, []
        return out

    def state(self) -> VehicleState:
        """The logged vehicle at the log time now (:attr:`t`: ``rate`` x wall seconds since the first :meth:`step`),
        as of the messages applied so far: position and velocity from GLOBAL_POSITION_INT, attitude from ATTITUDE,
        battery percent (None while the log has not reported it, or reports it unknown), armed and mode from the
        HEARTBEAT, in-air from EXTENDED_SYS_STATE's landed state (else armed and above 0.5 m), link health from
        the gaps between the log's heartbeats."""
        att = self._att
        return VehicleState(t=self._log_now(), position=self._pos, velocity=self._vel, roll=att.roll,
                            pitch=att.pitch, yaw=att.yaw, battery_pct=self._bat, armed=self._armed,
                            in_air=self._in_air(), link_ok=self._link_ok, mode=self._mode, home=self.home)

    def _in_air(self) -> bool:
        if self._landed_state is not None:
            return self._landed_state in _MAV_LANDED_STATE_IN_AIR
        return self._armed and self._pos[2] > 0.5

    def _odometry(self) -> Odometry:
        """The logged fix (else home), applied up to the log time of the last step, with the battery voltage."""
        geo = self._geo or self.home
        return Odometry(robot_id=self.robot_id, t=self._t_applied, position=tuple(float(v) for v in self._pos),
                        geodetic=geo, velocity=tuple(float(v) for v in self._vel), attitude=self._att,
                        battery_pct=None if self._bat is None else min(max(self._bat, 0.0), 100.0),
                        battery_voltage=self._volt,
                        armed=self._armed, in_air=self._in_air())


class NoCommands:
    """The command groups (``actions`` and ``guidance``) of a backend that only reports: every command raises
    :class:`~aerodaas.backends.base.NotNavigable` naming the robot, the backend and the command."""

    def __init__(self, robot_id: str, kind: str) -> None:
        self.robot_id, self.kind = robot_id, kind

    def _refuse(self, command: str) -> NoReturn:
        raise NotNavigable(f"robot {self.robot_id!r}: backend {self.kind!r} is not navigable; {command} is "
                           f"not possible (is_navigable() is False)")

    def arm(self) -> None:
        self._refuse("arm")

    def disarm(self) -> None:
        self._refuse("disarm")

    def takeoff(self, altitude_m: float) -> None:
        self._refuse("takeoff")

    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        self._refuse("goto")

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        self._refuse("set_velocity")

    def hold(self) -> None:
        self._refuse("hold")

    def land(self) -> None:
        self._refuse("land")

    def return_to_launch(self) -> bool:
        self._refuse("return_to_launch")


class McapCameraReplay:
    """A camera channel of an MCAP recording (``foxglove.CompressedImage``, JPEG or PNG) as a frame source.

    ``path``: the recording; ``topic``: e.g. ``/drone1/camera/cam0`` (AeroDaaS records cameras on
    ``/<robot>/camera/<sensor>``). Frame times ``t`` are seconds since ``start_ns`` (default: the recording's
    first message on any topic, which for AeroDaaS recordings is mission time 0). Frames are decoded lazily with
    ``cv2.imdecode`` to ``(H, W, 3) uint8 BGR``; only the compressed bytes are kept in memory.

    Raises FileNotFoundError / ValueError (not an MCAP file, ``topic`` absent or not a CompressedImage channel,
    naming the topics that are there)."""

    def __init__(self, path: str | os.PathLike, topic: str, start_ns: int | None = None) -> None:
        from aerodaas.recording.reader import read_messages, summarize_mcap  # lazy: heavy cv2, mcap, protobuf

        self.path, self.topic = str(path), topic
        summary = summarize_mcap(self.path)
        self.start_ns = int(summary["start_ns"] or 0) if start_ns is None else int(start_ns)
        times: list[int] = []
        self._data: list[bytes] = []
        for _, schema, t_ns, msg in read_messages(self.path, topics=[topic]):
            if schema != "foxglove.CompressedImage":
                raise ValueError(f"topic {topic!r} in {self.path!r} carries {schema!r}, not foxglove.CompressedImage")
            times.append(t_ns)
            self._data.append(bytes(msg.data))
        if not times:
            topics = [c["topic"] for c in summary["channels"]]
            raise ValueError(f"topic {topic!r} not found (or empty) in {self.path!r}; topics there: {topics}")
        order = np.argsort(np.asarray(times, np.int64), kind="stable")
        self._data = [self._data[i] for i in order]
        self.times_ns = [times[i] for i in order]
        #: frame times, seconds since ``start_ns``
        self.times = [(t - self.start_ns) / 1e9 for t in self.times_ns]

    def __len__(self) -> int:
        return len(self._data)

    def frame(self, i: int) -> np.ndarray:
        """Frame ``i`` decoded, ``(H, W, 3) uint8 BGR``. Raises IndexError / ValueError (undecodable bytes)."""
        import cv2  # lazy: heavy cv2

        img = cv2.imdecode(np.frombuffer(self._data[i], np.uint8), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f"{self.path!r} {self.topic!r}: frame {i} is not a decodable image")
        return img

    def frame_at(self, t: float) -> tuple[np.ndarray, float] | None:
        """The newest frame at or before ``t`` seconds and its time; None before the first frame."""
        i = bisect.bisect_right(self.times, t) - 1
        return None if i < 0 else (self.frame(i), self.times[i])

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        """``(t, frame)`` in time order."""
        for i, t in enumerate(self.times):
            yield t, self.frame(i)
