"""Vehicle backend ``gusty_sim``: the embedded simulator with wind gusts.

Every ``period_s`` seconds of simulated time a gust adds ``gust_mps`` m/s of horizontal velocity in a random
direction (seeded) to the simulated vehicle; the simulator's controller then recovers under its acceleration limit.
Each gust is reported as a ``wind_gust`` event (recorded on ``/<robot>/events``). Settings: ``robots[].
backend_config`` = :class:`WindConfig`.
"""
from __future__ import annotations

import math

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from aerodaas.backends.sim import SimBackend


class WindConfig(BaseModel):
    """``backend_config`` of ``gusty_sim``: gust strength (m/s), period (s of simulated time), random seed."""

    model_config = ConfigDict(extra="forbid")

    gust_mps: float = Field(default=1.0, ge=0, le=15.0)
    period_s: float = Field(default=2.0, gt=0, le=3600)
    seed: int = Field(default=0, ge=0)


class GustySimBackend(SimBackend):
    """See the module docstring."""

    kind = "gusty_sim"
    Config = WindConfig
    produces = ("odometry", "events:wind_gust")

    def __init__(self, cfg) -> None:
        super().__init__(cfg)
        self.wind = self.options(cfg)
        self._rng = np.random.default_rng(self.wind.seed)
        self._next_gust = self.wind.period_s
        self._events: list[dict] = []
        self.gusts = 0

    def step(self, dt: float) -> None:
        super().step(dt)
        v = self.vehicle
        if v.t >= self._next_gust:
            self._next_gust += self.wind.period_s
            if v.state.in_air and self.wind.gust_mps > 0:
                heading = float(self._rng.uniform(0.0, 360.0))
                kick = self.wind.gust_mps * np.array([math.cos(math.radians(heading)),
                                                      math.sin(math.radians(heading)), 0.0])
                v.state.velocity[:] = v.state.velocity + kick
                self.gusts += 1
                self._events.append({"event": "wind_gust", "speed_mps": self.wind.gust_mps,
                                     "direction_deg": heading, "n": self.gusts})

    def drain_events(self) -> list[dict]:
        out, self._events = self._events + super().drain_events(), []
        return out
