"""Latency statistics of the analytics runtime: :class:`Samples`, a bounded (seeded reservoir) sample of floats
with nearest-rank percentiles."""
from __future__ import annotations

import math
import random
from typing import Iterable, Sequence

__all__ = ["Samples"]


class Samples:
    """A bounded sample of floats (a seeded reservoir beyond ``cap``) with percentiles, for latency statistics."""

    def __init__(self, cap: int = 200_000, seed: int = 0) -> None:
        self.cap = cap
        self.values: list[float] = []
        self.n = 0
        self.max = -math.inf
        self._rng = random.Random(seed)

    def add(self, v: float) -> None:
        self.n += 1
        if v > self.max:
            self.max = v
        if len(self.values) < self.cap:
            self.values.append(v)
        else:
            j = self._rng.randrange(self.n)
            if j < self.cap:
                self.values[j] = v

    def extend(self, values: Iterable[float]) -> None:
        for v in values:
            self.add(v)

    @staticmethod
    def summarize(values: Sequence[float], n: int | None = None, vmax: float | None = None) -> dict:
        """``{"n", "p01", "p50", "p99", "max", "mean"}`` of ``values`` (nearest-rank percentiles); zeros when empty."""
        if not values:
            return {"n": 0, "p01": 0.0, "p50": 0.0, "p99": 0.0, "max": 0.0, "mean": 0.0}
        s = sorted(values)

        def q(p: float) -> float:
            return s[min(len(s) - 1, max(0, math.ceil(p * len(s)) - 1))]

        return {"n": int(n if n is not None else len(s)), "p01": q(0.01), "p50": q(0.50), "p99": q(0.99),
                "max": float(vmax if vmax is not None else s[-1]), "mean": sum(s) / len(s)}

    def summary(self) -> dict:
        return self.summarize(self.values, self.n, self.max if self.n else None)
