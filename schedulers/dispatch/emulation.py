"""Emulated variability of an analytics run: seeded random streams (:func:`seeded_rng`), multiplicative jitter
on profiled execution times (:class:`Jitter`) and the extra network latency of a cloud round trip
(:class:`NetworkModel`, with variability :class:`Episode` s). Every draw is seeded per task, so runs are
reproducible in every process whatever the order of events.
"""
from __future__ import annotations

import hashlib
import math
import random
import re
from dataclasses import asdict, dataclass
from typing import Any, Iterable, Sequence

__all__ = ["seeded_rng", "Jitter", "Episode", "NetworkModel"]


def seeded_rng(*keys: Any) -> random.Random:
    """A ``random.Random`` seeded from ``keys`` (ints/strings) through BLAKE2b: the same keys give the same stream
    in every process (unlike ``hash``), so per-task draws do not depend on the order of events."""
    digest = hashlib.blake2b(repr(keys).encode(), digest_size=8).digest()
    return random.Random(int.from_bytes(digest, "little"))


@dataclass(frozen=True)
class Jitter:
    """Multiplicative jitter on a profiled execution time: ``factor`` is 1 for ``kind="none"``, ``exp(N(-σ²/2, σ))``
    for ``"lognormal"`` (mean 1, always positive), ``max(0.05, N(1, σ))`` for ``"normal"``. ``sigma`` is a fraction
    of the profile time (0.05 = 5 %)."""

    kind: str = "lognormal"
    sigma: float = 0.05

    def __post_init__(self) -> None:
        if self.kind not in ("none", "lognormal", "normal"):
            raise ValueError(f"jitter kind must be none, lognormal or normal, got {self.kind!r}")
        if not (self.sigma >= 0 and math.isfinite(self.sigma)):
            raise ValueError(f"jitter sigma must be a finite number >= 0, got {self.sigma!r}")

    @classmethod
    def parse(cls, spec: str) -> "Jitter":
        """``"none"``, ``"lognormal:0.1"`` or ``"normal:0.05"``. Raises ValueError naming the spec."""
        kind, _, sigma = spec.strip().partition(":")
        try:
            return cls(kind, float(sigma) if sigma else (0.0 if kind == "none" else 0.05))
        except ValueError as e:
            raise ValueError(f"jitter {spec!r}: {e}") from None

    def factor(self, rng: random.Random) -> float:
        if self.kind == "none" or self.sigma == 0:
            return 1.0
        if self.kind == "lognormal":
            return math.exp(rng.gauss(-self.sigma ** 2 / 2, self.sigma))
        return max(0.05, rng.gauss(1.0, self.sigma))

    def __str__(self) -> str:
        return "none" if self.kind == "none" else f"{self.kind}:{self.sigma:g}"


@dataclass(frozen=True)
class Episode:
    """Network variability episode: ``add_ms`` extra latency for tasks sent between ``start_s`` and ``end_s``
    (seconds since the run's start)."""

    start_s: float
    end_s: float
    add_ms: float


class NetworkModel:
    """Extra network latency (ms) of one cloud round trip, added to the cloud executor's hold.

    The workload's ``cloud_ms`` is the measured AWS Lambda round trip (network included), so the default adds
    nothing. Components (summed):

    * a base distribution: ``const:MS``, ``normal:MEAN,SD`` (truncated at 0), ``lognormal:MEDIAN,SIGMA``;
    * episodes ``+MS@T1-T2``: MS more for tasks sent between T1 and T2 seconds of the run (the paper's latency
      variability experiments inject such steps);
    * a random walk ``walk:STEP,MAX[,EVERY]``: every EVERY s (default 1) the offset moves by ±STEP ms, kept within
      [0, MAX]; the walk is seeded, so it is the same in every process.

    A task's draw is seeded by ``(seed, task key)``, so runs are reproducible whatever the order of events. Half of
    the latency is applied before execution (uplink, after the cloud's re-check: see
    :mod:`aerodaas.schedulers.dispatch.dispatcher`), half after (downlink).
    """

    _EPISODE = re.compile(r"^\+(?P<ms>\d+(\.\d*)?)@(?P<t1>\d+(\.\d*)?)-(?P<t2>\d+(\.\d*)?)$")

    def __init__(self, base: tuple = ("none",), episodes: Sequence[Episode] = (),
                 walk: tuple[float, float, float] | None = None, seed: int = 0) -> None:
        self.base = tuple(base)
        self.episodes = tuple(episodes)
        self.walk = walk
        self.seed = int(seed)
        self._walk_values: list[float] = [0.0]
        self._walk_rng = seeded_rng("walk", self.seed)

    @classmethod
    def parse(cls, specs: Iterable[str] | str | None, seed: int = 0) -> "NetworkModel":
        """Build from spec strings (see the class docstring; several may be given, comma- or list-separated).
        Raises ValueError naming a malformed spec."""
        if specs is None:
            specs = []
        if isinstance(specs, str):
            specs = [specs]
        items = [item for spec in specs for item in re.split(r"[;\s]+", spec.strip()) if item]
        base: tuple = ("none",)
        episodes, walk = [], None
        for s in items:
            try:
                if m := cls._EPISODE.match(s):
                    t1, t2 = float(m["t1"]), float(m["t2"])
                    if t2 <= t1:
                        raise ValueError("the episode must end after it starts")
                    episodes.append(Episode(t1, t2, float(m["ms"])))
                    continue
                kind, _, args = s.partition(":")
                vals = [float(v) for v in args.split(",")] if args else []
                if any(not math.isfinite(v) or v < 0 for v in vals):
                    raise ValueError("values must be finite numbers >= 0")
                if kind == "none" and not vals:
                    base = ("none",)
                elif kind == "const" and len(vals) == 1:
                    base = ("const", vals[0])
                elif kind == "normal" and len(vals) == 2:
                    base = ("normal", vals[0], vals[1])
                elif kind == "lognormal" and len(vals) == 2 and vals[0] > 0:
                    base = ("lognormal", vals[0], vals[1])
                elif kind == "walk" and len(vals) in (2, 3) and (len(vals) == 2 or vals[2] > 0):
                    walk = (vals[0], vals[1], vals[2] if len(vals) == 3 else 1.0)
                else:
                    raise ValueError("expected const:MS, normal:MEAN,SD, lognormal:MEDIAN,SIGMA, +MS@T1-T2 "
                                     "or walk:STEP,MAX[,EVERY]")
            except ValueError as e:
                raise ValueError(f"network-variability {s!r}: {e}") from None
        return cls(base, episodes, walk, seed)

    def describe(self) -> dict:
        return {"base": list(self.base), "episodes": [asdict(e) for e in self.episodes],
                "walk": None if self.walk is None else {"step_ms": self.walk[0], "max_ms": self.walk[1],
                                                        "every_s": self.walk[2]}}

    def offset_ms(self, t_ms: float) -> float:
        """The time-dependent part (episodes + random walk) at run time ``t_ms``."""
        t_s = t_ms / 1000.0
        extra = sum(e.add_ms for e in self.episodes if e.start_s <= t_s < e.end_s)
        if self.walk is not None and t_s > 0:
            step, vmax, every = self.walk
            i = int(t_s // every)
            while len(self._walk_values) <= i:
                v = self._walk_values[-1] + (step if self._walk_rng.random() < 0.5 else -step)
                self._walk_values.append(min(vmax, max(0.0, v)))
            extra += self._walk_values[i]
        return extra

    def sample(self, t_ms: float, rng: random.Random) -> float:
        """Extra round-trip latency (ms) for a task sent at run time ``t_ms``, drawn from ``rng``."""
        kind = self.base[0]
        if kind == "const":
            v = self.base[1]
        elif kind == "normal":
            v = max(0.0, rng.gauss(self.base[1], self.base[2]))
        elif kind == "lognormal":
            v = self.base[1] * math.exp(rng.gauss(0.0, self.base[2]))
        else:
            v = 0.0
        return v + self.offset_ms(t_ms)
