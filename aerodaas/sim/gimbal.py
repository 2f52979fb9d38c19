"""The simulator's camera gimbal: a :class:`~aerodaas.navigation.gimbal.GimbalModel` that slews towards what the
drone commands (pitch/yaw, or a region of interest it keeps in view from the vehicle's pose), reporting its
attitude on the vehicle's clock as :class:`~aerodaas.protocol.gimbal.GimbalAttitude`."""
from __future__ import annotations

from typing import Any, Callable

from aerodaas.navigation.gimbal import GimbalLimits, GimbalModel, quaternion_from_euler, roi_angles
from aerodaas.protocol import gimbal as proto

__all__ = ["SimGimbal"]


class SimGimbal:
    """A two-axis gimbal on a simulated vehicle, within ``limits``, starting at ``pitch_deg`` (the camera's mount:
    -90 nadir) and yaw 0 (the nose). :meth:`point` takes a gimbal command, :meth:`step` turns it for ``dt``
    seconds from the vehicle's pose, :meth:`attitude` reports it at a given time and :meth:`latest` /
    :meth:`drain` at the vehicle's time now (``clock()``, seconds): the backend contract's gimbal
    (:class:`aerodaas.backends.base.Gimbal`)."""

    def __init__(self, limits: GimbalLimits, pitch_deg: float = -90.0,
                 clock: Callable[[], float] = lambda: 0.0) -> None:
        self.model = GimbalModel(limits, pitch_deg, 0.0)
        self.roi_enu: tuple[float, float, float] | None = None
        self._clock = clock
        self._drained: proto.GimbalAttitude | None = None

    def point(self, cmd: proto.GimbalCommand) -> None:
        """Aim (pitch/yaw, degrees, clamped to the limits), follow a region of interest (ENU metres), or release it
        (the gimbal stays where it points). Raises TypeError for anything else."""
        if isinstance(cmd, proto.GimbalPoint):
            self.roi_enu = None
            self.model.point(cmd.pitch_deg, cmd.yaw_deg)
        elif isinstance(cmd, proto.GimbalRoi):
            self.roi_enu = (float(cmd.x), float(cmd.y), float(cmd.z))
        elif isinstance(cmd, proto.GimbalRelease):
            self.roi_enu = None
            self.model.point(self.model.pitch_deg, self.model.yaw_deg)
        else:
            raise TypeError(f"not a gimbal command: {cmd!r}")

    def step(self, dt: float, position_enu: Any, yaw_enu_deg: float) -> None:
        """Turn for ``dt`` seconds; with a region of interest, re-aim at it from the vehicle's pose first."""
        if self.roi_enu is not None:
            self.model.point(*roi_angles(tuple(float(c) for c in position_enu), float(yaw_enu_deg), self.roi_enu))
        self.model.step(dt)

    def attitude(self, t: float) -> proto.GimbalAttitude:
        """The attitude now, stamped with vehicle time ``t`` (s)."""
        p, y = self.model.pitch_deg, self.model.yaw_deg
        return proto.GimbalAttitude(t=t, q=quaternion_from_euler(0.0, p, y), roll_deg=0.0, pitch_deg=p, yaw_deg=y,
                                    source="sim")

    def latest(self) -> proto.GimbalAttitude:
        """The attitude now, on the vehicle's clock."""
        return self.attitude(self._clock())

    def drain(self) -> list[proto.GimbalAttitude]:
        """The attitude now when it changed since the last call (one report per change), else nothing."""
        att = self.latest()
        if att == self._drained:
            return []
        self._drained = att
        return [att]

    def state(self) -> dict:
        """What a checkpoint keeps (angles, target, region of interest)."""
        return {"pitch": self.model.pitch_deg, "yaw": self.model.yaw_deg, "target": self.model.target,
                "roi": self.roi_enu}

    def restore(self, s: dict) -> None:
        """Take back :meth:`state`."""
        self.model.pitch_deg, self.model.yaw_deg = s["pitch"], s["yaw"]
        self.model.target, self.roi_enu = tuple(s["target"]), s["roi"]
