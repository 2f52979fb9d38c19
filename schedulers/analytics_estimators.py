"""Cloud-latency estimators shared by the just-in-time analytics schedulers (DEMS, DEMS-A, GEMS, GAINPLAN, ...).

A just-in-time policy holds a task until its cloud trigger, ``deadline - estimate - 10 ms`` (the reference's
``TaskCreation.cloudBuffer``), and releases it then; the estimate decides the margin a release leaves against the
real round trip. So that policies can be compared on their *rules* rather than on their estimators (the "fair
margin" option of ``aerodaas bench schedulers --estimator``), every such policy accepts ``estimator=SPEC``:

* ``profile`` — the workload's ``cloud_ms`` forever (DEMS and GEMS in the reference code);
* ``mean[:K]`` — DEMS-A's estimate (``PostProcessing.java`` + ``TriggerUpdate.java``): once the window of the last
  K (default 10) observed round trips is full, its mean replaces the estimate whenever they differ by > 10 ms;
* ``max[:K]`` — the largest of the last K (default 5) round trips (GAINPLAN's default);
* ``pQ[:K]`` — the Q-th percentile (nearest rank, 0 < Q <= 100) of the last K (default 20) round trips.

Every estimator starts at the profile's ``cloud_ms`` and learns only from cloud completions (as the reference's
``PostProcessing``). Times in ms.
"""
from __future__ import annotations

import math
import re
from abc import ABC, abstractmethod
from collections import deque

from aerodaas.schedulers.analytics_base import Workload

__all__ = ["LatencyEstimator", "ProfileEstimator", "WindowMeanEstimator", "RecentMaxEstimator",
           "PercentileEstimator", "make_estimator", "ESTIMATOR_HELP"]

ESTIMATOR_HELP = "profile, mean[:K] (DEMS-A), max[:K] (GAINPLAN) or pQ[:K] (percentile Q of the last K)"


class LatencyEstimator(ABC):
    """Per-model cloud round-trip estimate (ms). Subclasses implement :meth:`_from_window`."""

    #: the spec this estimator was built from (reported in the benchmark JSON)
    spec: str = ""

    def __init__(self, workload: Workload, window: int) -> None:
        if window < 1:
            raise ValueError(f"estimator window must be >= 1, got {window}")
        self.window = int(window)
        self.profile = {m: p.cloud_ms for m, p in workload.models.items()}
        self.samples = {m: deque(maxlen=self.window) for m in workload.models}

    def observe(self, model: str, latency_ms: float) -> None:
        """One completed cloud round trip of ``model`` (ms)."""
        self.samples[model].append(float(latency_ms))

    def refill(self, model: str, latency_ms: float) -> None:
        """Fill the whole window with one observation (DEMS-A's reset after a cool-down probe)."""
        self.samples[model].clear()
        self.samples[model].extend([float(latency_ms)] * self.window)

    def value(self, model: str) -> float:
        """The current estimate for ``model`` (ms): the profile before any observation."""
        s = self.samples[model]
        return self._from_window(model, s) if s else self.profile[model]

    @abstractmethod
    def _from_window(self, model: str, s: deque) -> float:
        """The estimate (ms) from a non-empty window ``s`` of observed round trips of ``model``."""


class ProfileEstimator(LatencyEstimator):
    """The profile's ``cloud_ms``, never updated (DEMS, GEMS)."""

    spec = "profile"

    def __init__(self, workload: Workload) -> None:
        super().__init__(workload, 1)

    def observe(self, model: str, latency_ms: float) -> None:
        return None

    def refill(self, model: str, latency_ms: float) -> None:
        return None

    def _from_window(self, model: str, s: deque) -> float:
        return self.profile[model]


class WindowMeanEstimator(LatencyEstimator):
    """DEMS-A: the mean of the last ``window`` round trips replaces the estimate once the window is full and the
    two differ by more than ``drift_ms`` (Application.java: 10 entries, 10 ms)."""

    def __init__(self, workload: Workload, window: int = 10, drift_ms: float = 10.0) -> None:
        super().__init__(workload, window)
        self.drift_ms = float(drift_ms)
        self.estimate = dict(self.profile)
        self.spec = f"mean:{self.window}"

    def observe(self, model: str, latency_ms: float) -> None:
        super().observe(model, latency_ms)
        self._update(model)

    def refill(self, model: str, latency_ms: float) -> None:
        super().refill(model, latency_ms)
        self._update(model)

    def _update(self, model: str) -> None:
        buf = self.samples[model]
        if len(buf) == self.window:
            mean = sum(buf) / len(buf)
            if abs(mean - self.estimate[model]) > self.drift_ms:
                self.estimate[model] = mean

    def _from_window(self, model: str, s: deque) -> float:
        return self.estimate[model]  # moved only by _update (the profile until a full window drifts)


class RecentMaxEstimator(LatencyEstimator):
    """The largest of the last ``window`` round trips (reacts to a step after one late sample)."""

    def __init__(self, workload: Workload, window: int = 5) -> None:
        super().__init__(workload, window)
        self.spec = f"max:{self.window}"

    def _from_window(self, model: str, s: deque) -> float:
        return max(s)


class PercentileEstimator(LatencyEstimator):
    """The ``q``-th percentile (nearest rank) of the last ``window`` round trips."""

    def __init__(self, workload: Workload, q: float = 95.0, window: int = 20) -> None:
        if not 0 < q <= 100:
            raise ValueError(f"estimator percentile must be in (0, 100], got {q}")
        super().__init__(workload, window)
        self.q = float(q)
        self.spec = f"p{self.q:g}:{self.window}"

    def _from_window(self, model: str, s: deque) -> float:
        xs = sorted(s)
        return xs[max(0, math.ceil(self.q / 100.0 * len(xs)) - 1)]


_SPEC = re.compile(r"^(?P<kind>profile|mean|max|p(?P<q>\d+(\.\d*)?))(:(?P<k>\d+))?$")


def make_estimator(spec: str, workload: Workload) -> LatencyEstimator:
    """Build an estimator from ``spec`` (see the module docstring). Raises ValueError naming the spec."""
    m = _SPEC.match(str(spec).strip().lower())
    if not m or (m["kind"] == "profile" and m["k"]):
        raise ValueError(f"estimator {spec!r}: expected {ESTIMATOR_HELP}")
    k = int(m["k"]) if m["k"] else None
    if m["kind"] == "profile":
        return ProfileEstimator(workload)
    if m["kind"] == "mean":
        return WindowMeanEstimator(workload, k or 10)
    if m["kind"] == "max":
        return RecentMaxEstimator(workload, k or 5)
    return PercentileEstimator(workload, float(m["q"]), k or 20)
