"""The embedded simulator as a vehicle backend (see :mod:`aerodaas.sim.vehicle` for the flight model)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from aerodaas.model.types import Odometry
from aerodaas.config.backends import SimConfig
from aerodaas.sim.vehicle import SimVehicle
from aerodaas.backends.base import VehicleBackend


class SimBackend(VehicleBackend):
    """Drives a :class:`~aerodaas.sim.vehicle.SimVehicle`; time moves only in :meth:`step` (simulated seconds)."""

    kind = "sim"
    clock = "sim"
    Config = SimConfig  # no settings of its own: the vehicle is the robot's limits, battery and noise

    def __init__(self, cfg) -> None:  # cfg: aerodaas.config.RobotConfig
        super().__init__(cfg.id, cfg.home)
        self.vehicle = SimVehicle(cfg.id, cfg.home, cfg.limits, cfg.battery, cfg.noise)

    @property
    def t(self) -> float:
        return self.vehicle.t

    def checkpoint(self) -> dict:
        """The simulated vehicle's state, setpoint, clock and noise generator (deep copies)."""
        import copy

        v = self.vehicle
        return copy.deepcopy({"state": v.state, "setpoint": v.setpoint, "t": v.t, "rng": v.noise_state})

    def restore(self, state: dict) -> None:
        import copy

        v, s = self.vehicle, copy.deepcopy(state)
        v.state, v.setpoint, v.t = s["state"], s["setpoint"], s["t"]
        v.noise_state = s["rng"]

    def step(self, dt: float) -> None:
        self.vehicle.step(dt)

    @property
    def position(self) -> np.ndarray:
        return self.vehicle.state.position

    @property
    def velocity(self) -> np.ndarray:
        return self.vehicle.state.velocity

    @property
    def yaw(self) -> float:
        return self.vehicle.state.yaw

    @property
    def armed(self) -> bool:
        return self.vehicle.state.armed

    @property
    def in_air(self) -> bool:
        return self.vehicle.state.in_air

    @property
    def battery_pct(self) -> float:
        return self.vehicle.battery_pct

    def odometry(self) -> Odometry:
        return self.vehicle.odometry()

    def arm(self) -> None:
        self.vehicle.arm()

    def disarm(self) -> None:
        self.vehicle.disarm()

    def takeoff(self, altitude_m: float) -> None:
        self.vehicle.takeoff(altitude_m)

    def goto(self, target_enu: Sequence[float], speed: float | None = None) -> None:
        self.vehicle.goto(tuple(target_enu), speed)

    def set_velocity(self, v_enu: Sequence[float], yaw_rate_dps: float = 0.0) -> None:
        self.vehicle.set_velocity(tuple(v_enu), yaw_rate_dps)

    def hold(self) -> None:
        self.vehicle.hold()

    def land(self) -> None:
        self.vehicle.land()
