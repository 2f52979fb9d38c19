"""Sensor type ``gas_concentration``: a gas sensor (ppm) on the drone, reading a Gaussian plume.

The plume: ``ppm = background_ppm + peak_ppm * exp(-d^2 / (2 * spread_m^2))`` where ``d`` is the horizontal
distance (metres, ENU) from the vehicle to the source at (``source_x``, ``source_y``), plus Gaussian noise of
``noise_ppm`` standard deviation (a steady-state plume without advection: a teaching model, not a dispersion model).
"""
from __future__ import annotations

import math

import numpy as np
from pydantic import BaseModel, Field

from aerodaas.plugins import SensorPlugin, SensorPluginConfig


class GasConfig(SensorPluginConfig):
    """``properties`` of a ``gas_concentration`` sensor (metres ENU from home, ppm)."""

    source_x: float = Field(default=0.0, description="plume source, metres east of home")
    source_y: float = Field(default=0.0, description="plume source, metres north of home")
    peak_ppm: float = Field(default=100.0, ge=0, le=1e6)
    spread_m: float = Field(default=10.0, gt=0, le=10_000)
    background_ppm: float = Field(default=0.4, ge=0, le=1e6)
    noise_ppm: float = Field(default=0.0, ge=0, le=1e6)
    seed: int = Field(default=0, ge=0)


class GasReading(BaseModel):
    """One reading: ``ppm`` at the vehicle's ENU position (metres) at vehicle time ``t`` (seconds)."""

    robot: str
    sensor: str
    t: float = Field(description="vehicle time, s")
    ppm: float = Field(description="gas concentration, parts per million")
    position: list[float] = Field(description="ENU metres from home where it was read")


class GasConcentrationSensor(SensorPlugin):
    """See the module docstring."""

    name = "gas_concentration"
    Config = GasConfig
    Message = GasReading

    def setup(self) -> None:
        self.rng = np.random.default_rng(self.config.seed)

    def sample(self, state, t: float) -> GasReading:
        c = self.config
        x, y, z = (float(v) for v in state.position)
        d2 = (x - c.source_x) ** 2 + (y - c.source_y) ** 2
        ppm = c.background_ppm + c.peak_ppm * math.exp(-d2 / (2.0 * c.spread_m ** 2))
        if c.noise_ppm:
            ppm = max(0.0, ppm + float(self.rng.normal(0.0, c.noise_ppm)))
        return GasReading(robot=self.robot_id, sensor=self.sensor_id, t=t, ppm=ppm, position=[x, y, z])
