"""A drone's odometry sensor: what it records and publishes of its vehicle's position. The simulator's state is taken
on the odometry sensor's rate; a real vehicle's own position samples are each recorded once, stamped with the
vehicle's time of the sample, none lost while the drone's clock thread waited. An object of its drone
(:attr:`~aerodaas.actors.drone.component.DroneComponent.odometry`), given the vehicle backend, the recorder and the subscribers
it publishes to; it knows nothing else of the drone."""
from __future__ import annotations

from typing import Any, Callable

from aerodaas.config.robot import sensor_class
from aerodaas.plugins.sensor import Delivery
from aerodaas.protocol.messages import OdometryMsg


class OdometryPublisher:
    """The odometry of robot ``robot_id`` flying ``backend``: recorded to ``recorder`` (None: not recorded; stamps
    in nanoseconds from ``t_ns(t)``, ``t`` vehicle seconds) and published on ``plane`` to ``cids``, at ``rate_hz``.
    :attr:`last` is the latest sample published (a dict of :class:`~aerodaas.app.models.Odometry`), :attr:`next_t`
    the vehicle time (s) of the next slot (checkpointed with the drone)."""

    def __init__(self, backend: Any, robot_id: str, recorder: Any, plane: Any, cids: list[str], rate_hz: float,
                 t_ns: Callable[[float], int]) -> None:
        self.backend, self.robot_id, self.recorder, self.plane, self.cids = backend, robot_id, recorder, plane, cids
        self.t_ns = t_ns
        self.period = 1.0 / rate_hz
        self.next_t = 0.0
        self.last: dict | None = None
        self._key: Any = None  # the backend's sample_key when its samples were last drained
        self._t: float | None = None  # the vehicle time of the last published sample
        self._fresh = False  # the mission ended: the next drain takes the newest sample only

    @staticmethod
    def rate_of(robot_cfg: Any) -> float:
        """The ``rate_hz`` (Hz) of the robot's odometry sensor, default 10."""
        rate = 10.0
        for s in robot_cfg.sensors:
            if sensor_class(s.type).delivery is Delivery.VEHICLE_STATE:
                rate = float(s.properties.get("rate_hz", 10.0))
        return rate

    def on_step(self, tok: Any = None) -> None:
        """After a step of the vehicle (the clock thread): a vehicle's own samples, each one, paced on its own time;
        the simulator's state on the odometry rate's grid (after a jump of the vehicle clock, no burst)."""
        b = self.backend
        if b.telemetry.sample_key is not None:
            self.publish(tok, paced=True)
        elif b.t + 1e-9 >= self.next_t:
            self.next_t += self.period
            if b.t > self.next_t + self.period:  # vehicle clock jumped: do not burst
                self.next_t = b.t + self.period
            self.publish(tok)

    def mission_ended(self) -> None:
        """The drone is no longer stepped: the next drain takes the newest sample only."""
        self._fresh = True

    def publish(self, tok: Any = None, *, paced: bool = False) -> None:
        """Record and publish odometry. The simulator (no ``sample_key``): its state now. A vehicle: each of its
        position samples not yet published (:meth:`~aerodaas.backends.base.VehicleBackend.drain_odometry`), oldest
        first, stamped with the vehicle's own time of the sample, never one twice, so a clock thread held up (a
        command waiting for its acknowledgement) loses none. ``paced`` (the clock thread): at most at the odometry
        sensor's ``rate_hz`` on the samples' own times (a sample within a quarter period of its slot counts, so a
        10 Hz stream whose stamps jitter is recorded whole at 10 Hz); otherwise (the end of a run) the newest sample
        is published even when that rate would skip it."""
        b = self.backend
        key = b.telemetry.sample_key
        if key is None:
            dump = getattr(b.telemetry, "odometry_json", None)  # the simulator's: no pydantic round trip per sample
            self._publish(dump() if dump is not None else b.telemetry.odometry().model_dump(mode="json"), tok)
            return
        if key == self._key:
            return
        self._key = key
        # the first (not what the vehicle sent before the run), or the first since the mission ended (the drone
        # was no longer stepped): the newest only
        fresh = self._t is None or self._fresh
        self._fresh = False
        samples = b.telemetry.drain_odometry(newest_only=fresh)
        if samples and fresh:  # the slots start here at the latest (a drone restored from a checkpoint as well)
            self.next_t = min(self.next_t, samples[-1].t)
        samples = [o for o in samples if self._t is None or o.t > self._t]
        slack = 0.25 * self.period
        for i, o in enumerate(samples):
            if o.t + slack < self.next_t and (paced or i < len(samples) - 1):
                continue
            self.next_t += self.period
            if o.t > self.next_t:  # after a gap in the samples: the slots go on from this one
                self.next_t = o.t + self.period
            self._t = o.t
            self._publish(o.model_dump(mode="json"), tok)

    def _publish(self, odom: dict, tok: Any) -> None:
        self.last = odom
        if self.recorder is not None:
            self.recorder.odometry(self.robot_id, self.t_ns(odom["t"]), odom)
        for cid in self.cids:
            self.plane.publish(cid, [OdometryMsg(robot=self.robot_id, sim_t=odom["t"], data=odom)], tok, inline=False)
