"""The analytics of ``aerodaas bench fleet``: colocated with every drone, so it lives in a module of its own that
imports only what it runs. A drone actor imports the module of each analytics class it is given (the class travels
by reference); from :mod:`aerodaas.bench.fleet` that was the benchmark's driver side too (the application API, the
local cluster, the progress display), memory every drone actor of the measured fleet carried for nothing."""
from __future__ import annotations

from typing import Any

import numpy as np

from aerodaas.analytics.base import Analytics

__all__ = ["FrameExposure"]


class FrameExposure(Analytics):
    """A lightweight analytics: mean brightness and the fraction of saturated pixels of every 8th pixel of a frame
    ((H, W, 3) uint8 BGR in; a dict out). Colocated with every drone of the fleet benchmark."""

    name = "exposure"

    def __init__(self) -> None:
        super().__init__()
        self.frames = 0
        self.per_robot: dict[str, int] = {}

    def process(self, frame: np.ndarray, meta: Any) -> dict:
        small = frame[::8, ::8]
        self.frames += 1
        rid = meta.robot_id if meta is not None else "?"
        self.per_robot[rid] = self.per_robot.get(rid, 0) + 1
        return {"robot": rid, "mean": float(small.mean()), "saturated": float((small >= 250).mean())}

    def stats(self) -> dict:
        return {"frames": self.frames, "per_robot": dict(self.per_robot)}
