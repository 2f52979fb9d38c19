"""PluginSensorComponent: runs one plug-in sensor (:class:`aerodaas.plugins.sensor.SensorPlugin`) inside its
drone's actor. The drone's clock calls :meth:`PluginSensorComponent.maybe_sample` after every step; when the
sensor is due (``rate_hz``, vehicle time) it samples the vehicle state, records the reading on
``/<robot>/<sensor id>`` with the plug-in's schema and publishes it to the sensor's subscribers as a
:class:`~aerodaas.protocol.messages.ValueMsg` (in lock-step, as part of the step's cascade)."""
from __future__ import annotations

from typing import Any

from aerodaas.protocol.messages import ValueMsg
from aerodaas.recording.health import ComponentKind, FailureCount, FailureLog


class PluginSensorComponent:
    """One configured plug-in sensor: ``spec`` is ``{"cid", "sensor", "cls", "properties"}`` from the plan
    (``cls`` is the plug-in class itself, carried to this actor)."""

    kind = "sensor"

    def __init__(self, plane: Any, spec: dict, robot_id: str, recorder: Any, epoch_ns: int) -> None:
        cls = spec["cls"]
        self.cid, self.sensor_id, self.robot_id = spec["cid"], spec["sensor"], robot_id
        self.plugin = cls(robot_id, spec["sensor"], cls.Config.model_validate(spec["properties"]))
        self.plugin.setup()
        self.plane, self.recorder, self.epoch_ns = plane, recorder, epoch_ns
        self.topic = f"/{robot_id}/{spec['sensor']}"
        self.schema = cls.schema_name()
        self.type = spec.get("type", cls.name)
        self.period = 1.0 / self.plugin.rate_hz
        self.next_t = 0.0
        self.readings = 0
        #: its samples and failures (every one counted; the first ones and then summaries recorded as events)
        self.health = FailureLog(FailureCount(ComponentKind.SENSOR, robot_id, spec["sensor"],
                                              limit=spec["max_failure_fraction"]))

    @property
    def errors(self) -> int:
        """Readings that raised since this actor (re)started from its checkpoint."""
        return self.health.count.failures

    def maybe_sample(self, backend: Any, tok: Any = None) -> None:
        """Take a reading if one is due at the backend's time ``backend.t``."""
        t = float(backend.t)
        if t + 1e-9 < self.next_t:
            return
        self.next_t += self.period
        if t > self.next_t + self.period:  # the vehicle clock jumped: do not burst
            self.next_t = t + self.period
        try:
            out = self.plugin.sample(backend.telemetry.odometry(), t)
            if out is None:
                return
            data = out.model_dump(mode="json") if hasattr(out, "model_dump") else dict(out)
        except Exception as e:  # noqa: BLE001 - a failing sensor loses its reading, never the flight
            self.health.attempt()
            self._record(t, self.health.failed(t, f"{type(e).__name__}: {e}"))
            return
        self.health.attempt()
        self.readings += 1
        if self.recorder is not None:
            self.recorder.json(self.topic, self.epoch_ns + int(t * 1e9), data, self.schema)
        self.plane.publish(self.cid, [ValueMsg(robot=self.robot_id, sim_t=t, data=data)], tok, inline=False)

    def _record(self, t: float, event: dict | None) -> None:
        """Record a failure event (:class:`~aerodaas.recording.health.FailureLog`: the first ones, then summaries)
        of vehicle time ``t`` (s) on the robot's events; None: nothing to record now."""
        if event is not None and self.recorder is not None:
            self.recorder.json(f"/{self.robot_id}/events", self.epoch_ns + int(t * 1e9),
                               {"robot": self.robot_id, "t": t, **event}, "aerodaas.MissionEvent")

    def finish(self, t: float) -> None:
        """The run ended at vehicle time ``t`` (s): the failures no event carried yet, as a summary event."""
        self._record(t, self.health.summary(t))

    def stats(self) -> dict:
        """``{"type", "schema", "readings", "topic", "errors", "health"}`` for the run's summary (``health``:
        :meth:`FailureCount.as_dict <aerodaas.recording.health.FailureCount.as_dict>`)."""
        return {"type": self.type, "schema": self.schema, "readings": self.readings, "topic": self.topic,
                "errors": self.errors, "health": self.health.count.as_dict()}
