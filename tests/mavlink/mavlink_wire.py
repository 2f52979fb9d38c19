"""A drone (:class:`~aerodaas.actors.drone.component.DroneComponent`) on a MAVLink backend with no socket: the test hands the
backend the vehicle's messages as its I/O thread would (through the wire format, so each has its own sequence
number), and the drone's recorder calls are kept in memory."""
from __future__ import annotations

import time

from pymavlink.dialects.v20 import common as mav

#: the vehicle's home (degrees, metres AMSL)
HOME = {"lat": 47.3977, "lon": 8.5456, "alt": 488.0}
_M_PER_DEG_LAT = 111_195.0


class MemoryRecorder:
    """The recorder's calls a drone makes: odometry kept (``odometry_rows``, the JSON dicts), the rest ignored."""

    def __init__(self) -> None:
        self.odometry_rows: list[dict] = []

    def odometry(self, robot: str, t_ns: int, odom: dict) -> None:
        self.odometry_rows.append(odom)

    def json(self, *args, **kwargs) -> None:
        pass


class WiredDrone:
    """``drone``, ``backend`` (connected as ``connect()`` leaves it after the autopilot's HEARTBEAT: system 1,
    component 1) and ``recorder``; :meth:`send` hands in any message, :meth:`position` a GLOBAL_POSITION_INT,
    :meth:`heartbeat` and :meth:`landed_state` the vehicle's state. ``rate_hz``: the odometry sensor's rate."""

    def __init__(self, rate_hz: float = 10.0) -> None:
        from aerodaas.actors.drone.component import DroneComponent

        from aerodaas.backends.mavlink import MavlinkBackend
        from aerodaas.config import MavlinkConfig, RobotConfig

        cfg = RobotConfig(id="q", backend="mavlink", home=HOME, mavlink=MavlinkConfig(),
                          sensors=[{"id": "odom", "type": "odometry", "properties": {"rate_hz": rate_hz}}])
        self.backend = MavlinkBackend(cfg)
        self.backend.link.attach(1, 1)
        self.recorder = MemoryRecorder()
        self.drone = DroneComponent("q/drone", cfg.model_dump(mode="json"), None, None, self.recorder, 0, 0, [], [],
                                    backend=self.backend)
        self._enc, self._dec = mav.MAVLink(None, srcSystem=1, srcComponent=1), mav.MAVLink(None)

    def send(self, m) -> None:
        buf = m.pack(self._enc)
        self._enc.seq = (self._enc.seq + 1) % 256
        self.backend.link.dispatch(self._dec.decode(bytearray(buf)), time.monotonic())

    def position(self, ms: int, north_m: float = 0.0, alt_m: float = 2.0) -> None:
        """GLOBAL_POSITION_INT at ``time_boot_ms`` ``ms``, ``north_m`` metres north of home, ``alt_m`` above it."""
        self.send(mav.MAVLink_global_position_int_message(
            ms, int((HOME["lat"] + north_m / _M_PER_DEG_LAT) * 1e7), int(HOME["lon"] * 1e7),
            int((HOME["alt"] + alt_m) * 1e3), int(alt_m * 1e3), 0, 0, 0, 0))

    def heartbeat(self, armed: bool) -> None:
        self.send(mav.MAVLink_heartbeat_message(2, 12, (mav.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0) | 1, 0, 4, 3))

    def landed_state(self, state: int) -> None:
        """EXTENDED_SYS_STATE with ``landed_state`` ``state`` (MAV_LANDED_STATE)."""
        self.send(mav.MAVLink_extended_sys_state_message(0, state))
