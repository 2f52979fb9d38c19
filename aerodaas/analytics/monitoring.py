"""The built-in odometry monitoring analytics (:class:`MonitoringAnalytics`): odometry in, watched values out."""
from __future__ import annotations

import math
from typing import Any, Iterable

from aerodaas.analytics.base import Analytics, source_robot

__all__ = ["MonitoringAnalytics"]


class MonitoringAnalytics(Analytics):
    """Watches odometry fields (any of ``battery``, ``height``, ``gps``, ``speed``) and reports them with running
    minima/maxima; raises warnings when a ``limits`` bound (e.g. ``{"battery": 20}`` percent minimum,
    ``{"height": 30}`` metres maximum) is crossed. Output: a dict per odometry message (``t`` s, ``robot``, the
    watched values). Shared by several drones, it keeps the minima/maxima per drone (``by_drone`` in
    :meth:`stats`; ``summary`` is over all drones) and names the drone in each warning."""

    name = "monitor"
    consumes, produces = ("odometry",), ("value",)
    FIELDS = ("battery", "height", "gps", "speed")

    def __init__(self, watch: Iterable[str] = ("battery", "height", "gps"), limits: dict[str, float] | None = None,
                 name: str | None = None) -> None:
        super().__init__(name)
        self.watch = list(watch)
        bad = [w for w in self.watch if w not in self.FIELDS + ("camera",)]
        if bad:
            raise ValueError(f"watch: unknown fields {bad}; choose from {list(self.FIELDS)}")
        self.limits = limits or {}
        self.warnings: list[str] = []

    @property
    def summary(self) -> dict[str, dict[str, float]]:
        """Minimum and maximum of each numeric watched field over every drone: ``{field: {"min", "max"}}``."""
        out: dict[str, dict[str, float]] = {}
        for per in self.drone_states().values():
            for k, s in per.items():
                o = out.setdefault(k, dict(s))
                o["min"], o["max"] = min(o["min"], s["min"]), max(o["max"], s["max"])
        return out

    def process(self, odom: dict, meta: Any) -> dict:
        robot = source_robot(odom, meta)
        per: dict[str, dict[str, float]] = self.drone_state(odom, meta, dict)
        vals: dict[str, Any] = {}
        if "battery" in self.watch:
            vals["battery"] = odom["battery_pct"]
        if "height" in self.watch:
            vals["height"] = odom["position"][2]
        if "speed" in self.watch:
            vals["speed"] = math.hypot(*odom["velocity"])
        if "gps" in self.watch:
            vals["gps"] = [odom["geodetic"]["lat"], odom["geodetic"]["lon"], odom["geodetic"]["alt"]]
        for k, v in vals.items():
            if isinstance(v, (int, float)):
                s = per.setdefault(k, {"min": v, "max": v})
                s["min"], s["max"] = min(s["min"], v), max(s["max"], v)
        who = f"{robot}: " if robot else ""
        if "battery" in self.limits and (vals.get("battery") if vals.get("battery") is not None else 100) \
                < self.limits["battery"]:
            self.warnings.append(f"{who}battery {vals['battery']:.1f}% below {self.limits['battery']}% at "
                                 f"t={odom['t']:.1f}s")
        if "height" in self.limits and vals.get("height", 0) > self.limits["height"]:
            self.warnings.append(f"{who}height {vals['height']:.1f} m above {self.limits['height']} m at "
                                 f"t={odom['t']:.1f}s")
        return {"t": odom["t"], "robot": robot, **vals}

    def stats(self) -> dict:
        return {"summary": self.summary, "by_drone": {r: {k: dict(v) for k, v in per.items()}
                                                      for r, per in self.drone_states().items()},
                "warnings": self.warnings[-5:]}
