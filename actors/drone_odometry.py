"""A drone's odometry: what it records and publishes of its vehicle's position. The simulator's state is taken on the
odometry sensor's rate; a real vehicle's own position samples are each recorded once, stamped with the vehicle's
time of the sample, none lost while the drone's clock thread waited. A mixin of
:class:`~aerodaas.actors.drone.DroneComponent`, whose state (``backend``, ``cfg``, ``recorder``, ``plane``,
``odom_cids``, ``odom_period``, ``next_odom``) it shares; split from that module so that each stays one concept."""
from __future__ import annotations

from typing import Any

from aerodaas.config.robot import sensor_class
from aerodaas.plugins.sensor import SensorDelivery
from aerodaas.protocol.messages import OdometryMsg


class OdometryPublisher:
    """Part of :class:`~aerodaas.actors.drone.DroneComponent`."""

    def _init_odometry(self) -> None:
        """The odometry sensor's period (``rate_hz`` of the robot's odometry sensor, default 10 Hz) and the drain's
        bookkeeping."""
        odom_rate = 10.0
        for s in self.cfg.sensors:
            if sensor_class(s.type).delivery is SensorDelivery.VEHICLE_STATE:
                odom_rate = float(s.properties.get("rate_hz", 10.0))
        self.odom_period = 1.0 / odom_rate
        self.next_odom = 0.0
        self._odom_key: Any = None  # the backend's sample_key when its samples were last drained
        self._odom_t: float | None = None  # the vehicle time of the last published sample
        self._odom_fresh = False  # the mission ended: the next drain takes the newest sample only

    def publish_odometry(self, tok: Any = None, *, paced: bool = False) -> None:
        """Record and publish odometry. The simulator (no ``sample_key``): its state now. A vehicle: each of its
        position samples not yet published (:meth:`~aerodaas.backends.base.VehicleBackend.drain_odometry`), oldest
        first, stamped with the vehicle's own time of the sample, never one twice, so a clock thread held up (a
        command waiting for its acknowledgement) loses none. ``paced`` (the clock thread): at most at the odometry
        sensor's ``rate_hz`` on the samples' own times (a sample within a quarter period of its slot counts, so a
        10 Hz stream whose stamps jitter is recorded whole at 10 Hz); otherwise (the end of a run) the newest sample
        is published even when that rate would skip it."""
        b = self.backend
        key = b.sample_key
        if key is None:
            self._publish(b.odometry().model_dump(mode="json"), tok)
            return
        if key == self._odom_key:
            return
        self._odom_key = key
        # the first (not what the vehicle sent before the run), or the first since the mission ended (the drone
        # was no longer stepped): the newest only
        fresh = self._odom_t is None or self._odom_fresh
        self._odom_fresh = False
        samples = b.drain_odometry(newest_only=fresh)
        if samples and fresh:  # the slots start here at the latest (a drone restored from a checkpoint as well)
            self.next_odom = min(self.next_odom, samples[-1].t)
        samples = [o for o in samples if self._odom_t is None or o.t > self._odom_t]
        slack = 0.25 * self.odom_period
        for i, o in enumerate(samples):
            if o.t + slack < self.next_odom and (paced or i < len(samples) - 1):
                continue
            self.next_odom += self.odom_period
            if o.t > self.next_odom:  # after a gap in the samples: the slots go on from this one
                self.next_odom = o.t + self.odom_period
            self._odom_t = o.t
            self._publish(o.model_dump(mode="json"), tok)

    def _publish(self, odom: dict, tok: Any) -> None:
        self.last_odom = odom
        if self.recorder is not None:
            self.recorder.odometry(self.cfg.id, self._t_ns(odom["t"]), odom)
        for cid in self.odom_cids:
            self.plane.publish(cid, [OdometryMsg(robot=self.cfg.id, sim_t=odom["t"], data=odom)], tok, inline=False)
