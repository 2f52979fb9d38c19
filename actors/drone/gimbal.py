"""A drone's camera gimbal: the gimbal commands it carries out (from the application, checked by the drone's safety
gate against the robot's ``gimbal`` limits, then sent to the vehicle backend) and the attitude it records on
``/<robot>/gimbal`` (``aerodaas.GimbalAttitude``: quaternion, roll/pitch/yaw degrees, vehicle time). An object of
its drone (:attr:`~aerodaas.actors.drone.component.DroneComponent.gimbal`); it knows nothing else of the drone."""
from __future__ import annotations

from typing import Any, Callable

from aerodaas.backends import BackendError
from aerodaas.navigation.gimbal import GimbalError, GimbalLimits
from aerodaas.navigation.safety import SafetyGate, SafetyViolation
from aerodaas.protocol import gimbal as proto

__all__ = ["DroneGimbal"]


class DroneGimbal:
    """The gimbal of robot ``robot_id`` on ``backend``, within ``limits`` (None: the robot has no ``gimbal``
    section, and every command raises :class:`GimbalError`), checked by ``gate``. Attitudes are recorded to
    ``recorder`` (None: not recorded; stamps from ``t_ns(t)``, ``t`` vehicle seconds) at ``rate_hz`` and at each
    command; ``event(kind, **fields)`` records the drone's events. ``pending``: commands the application gave
    before the mission started, carried out by :meth:`start`."""

    def __init__(self, backend: Any, robot_id: str, limits: GimbalLimits | None, gate: SafetyGate, recorder: Any,
                 t_ns: Callable[[float], int], event: Callable[..., None], rate_hz: float = 10.0,
                 pending: list | None = None) -> None:
        self.backend, self.robot_id, self.limits, self.gate = backend, robot_id, limits, gate
        self.recorder, self.t_ns, self.event = recorder, t_ns, event
        self.period = 1.0 / rate_hz
        self.pending = list(pending or [])
        self.topic = f"/{robot_id}/gimbal"
        self.next_t = 0.0
        self.recorded = 0
        self.recorded_t: float | None = None
        self.sent = 0
        self.latest: proto.GimbalAttitude | None = None

    def check(self, cmd: proto.GimbalCommand) -> None:
        """Raise :class:`GimbalError` (field and value named) when the robot has no gimbal or ``cmd`` is outside its
        limits; nothing is sent. The check is the drone's safety gate's (:meth:`SafetyGate.check_gimbal`)."""
        if self.limits is None:
            raise GimbalError(f"robot {self.robot_id!r} has no gimbal: its configuration has no 'gimbal' section")
        try:
            if isinstance(cmd, proto.GimbalPoint):
                self.gate.check_gimbal(self.limits, cmd.pitch_deg, cmd.yaw_deg)
            elif isinstance(cmd, proto.GimbalRoi):
                self.gate.check_gimbal(self.limits, roi_enu=(cmd.x, cmd.y, cmd.z))
            elif not isinstance(cmd, proto.GimbalRelease):
                raise GimbalError(f"robot {self.robot_id!r}: not a gimbal command: {cmd!r}", "command", repr(cmd))
        except SafetyViolation as e:
            raise GimbalError(f"robot {self.robot_id!r}: {e.reason}", e.field, e.value) from None

    def command(self, cmd: proto.GimbalCommand) -> None:
        """Check ``cmd`` (:meth:`check`), send it to the backend and record a ``gimbal_command`` event. A refusal
        by the gate is recorded as ``command_rejected`` and raised as GimbalError; the vehicle's refusal is recorded
        as ``gimbal_refused`` and raised as the backend's error. Caller holds the drone's lock."""
        try:
            self.check(cmd)
        except GimbalError as e:
            self.event("command_rejected", item="gimbal", field=e.field, value=repr(e.value), reason=str(e))
            raise
        try:
            gimbal = self.backend.gimbal
            if gimbal is None:
                raise BackendError(f"robot {self.robot_id!r}: backend {self.backend.kind!r} has no gimbal")
            gimbal.point(cmd)
        except (BackendError, ValueError) as e:
            self.event("gimbal_refused", error=str(e), **cmd.describe())
            raise
        self.sent += 1
        # the attitude the command was given from is in the recording even between two of its rate slots
        if self.latest is not None and self.latest.t != self.recorded_t:
            self._record(self.latest)
        self.event("gimbal_command", **cmd.describe())

    def start(self) -> None:
        """Carry out the commands given before the mission started, in order (at take-off); a refusal is recorded
        and the flight goes on."""
        todo, self.pending = self.pending, []
        for cmd in todo:
            try:
                self.command(cmd)
            except (BackendError, ValueError):
                pass  # recorded by command()

    def on_step(self) -> None:
        """After a step of the vehicle: record the attitudes the backend reported (each once, at most at
        ``rate_hz`` on vehicle time; :meth:`command` also records the attitude it was given from)."""
        if self.limits is None:
            return
        gimbal = self.backend.gimbal
        for att in gimbal.drain() if gimbal is not None else []:
            self.latest = att
            if att.t + 1e-9 < self.next_t:
                continue
            # the next slot on the period's grid, or (after a gap in the reports) one period after this one
            self.next_t = self.next_t + self.period if att.t < self.next_t + self.period else att.t + self.period
            self._record(att)

    def _record(self, att: proto.GimbalAttitude) -> None:
        self.recorded += 1
        self.recorded_t = att.t
        if self.recorder is not None:
            self.recorder.json(self.topic, self.t_ns(att.t), att.record(self.robot_id), "aerodaas.GimbalAttitude")

    def attitude(self) -> dict | None:
        """The latest attitude (``aerodaas.GimbalAttitude`` fields), None before the first."""
        return None if self.latest is None else self.latest.record(self.robot_id)
