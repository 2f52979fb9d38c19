"""Which track is moving: the ground speed of each tracked object from its geo-located fixes over
a time window, and the rule :class:`~aerodaas.analytics.follow.FollowAnalytics` uses to follow the *moving* target
rather than a parked one (:class:`MovingTarget`, :class:`TrackMotion`)."""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ["MovingTarget", "TrackMotion"]


@dataclass(frozen=True)
class MovingTarget:
    """Follow only a track that moves: a track may be adopted as the follow target only when its ground speed,
    fitted over the last ``window_s`` seconds of its geo-located fixes, is at least ``min_speed_mps`` (m/s).
    Once adopted, the target is kept while ByteTrack keeps its id, even if it stops (a car at a junction).

    Defaults: 0.5 m/s over 1.0 s, from at least ``min_fixes`` = 3 fixes spanning at least half the window.
    Why these: a nadir camera at 16 m over a 640 px, 78° image samples about 4 cm/px, and a box centre jitters by
    a few pixels between frames, so a parked car's fitted speed stays near 0.1–0.2 m/s; the simulated
    vehicle-tracking car drives at 1 m/s and more (``apps/vehicle_tracking.json``). Walking persons (0.25–0.4 m/s in
    the person apps) are below the default: lower ``min_speed_mps`` for them. Fixes from boxes touching the image
    border are not used (:attr:`border_px`): a vehicle cut by the frame edge has its box centre slide with the
    drone's motion, which would make a parked car look like it drives at the drone's speed.

    The speed is the least-squares slope of x(t) and y(t) (ENU metres over capture time, s) on the fixes in the
    window — a straight-line fit, so one noisy fix moves it less than a two-point difference would.
    :meth:`check` raises ValueError naming the field and the value."""

    min_speed_mps: float = 0.5
    window_s: float = 1.0
    min_fixes: int = 3
    border_px: float = 2.0

    def check(self) -> None:
        """ValueError naming the field and the value for a threshold or window that cannot work."""
        if not np.isfinite(self.min_speed_mps) or self.min_speed_mps <= 0:
            raise ValueError(f"MovingTarget.min_speed_mps must be > 0 m/s, got {self.min_speed_mps!r}")
        if not np.isfinite(self.window_s) or self.window_s <= 0:
            raise ValueError(f"MovingTarget.window_s must be > 0 s, got {self.window_s!r}")
        if int(self.min_fixes) != self.min_fixes or self.min_fixes < 2:
            raise ValueError(f"MovingTarget.min_fixes must be an integer >= 2, got {self.min_fixes!r}")
        if not np.isfinite(self.border_px) or self.border_px < 0:
            raise ValueError(f"MovingTarget.border_px must be >= 0 px, got {self.border_px!r}")


class TrackMotion:
    """The recent geo-located fixes of each track id (one drone's; kept by its follow state) and their ground
    speed under a :class:`MovingTarget` rule."""

    def __init__(self, rule: MovingTarget) -> None:
        self.rule = rule
        self._fixes: dict[int, deque[tuple[float, float, float]]] = {}

    def add(self, track_id: int, t: float, xy: tuple[float, float] | np.ndarray) -> None:
        """Record track ``track_id`` at ground position ``xy`` (ENU metres) at capture time ``t`` (s); fixes older
        than the window before ``t`` are dropped, and a fix not newer than the track's last one is ignored."""
        q = self._fixes.setdefault(track_id, deque())
        if q and t <= q[-1][0]:
            return
        q.append((float(t), float(xy[0]), float(xy[1])))
        while q and q[0][0] < t - self.rule.window_s:
            q.popleft()

    def forget_except(self, track_ids: set[int]) -> None:
        """Drop the fixes of every track not in ``track_ids`` (the tracker's live ids)."""
        for tid in [k for k in self._fixes if k not in track_ids]:
            del self._fixes[tid]

    def speed(self, track_id: int) -> float | None:
        """Ground speed (m/s) of ``track_id`` fitted over its fixes in the window, or None while there are fewer
        than ``min_fixes`` of them or they span less than half the window (not enough to tell)."""
        q = self._fixes.get(track_id)
        if not q or len(q) < self.rule.min_fixes:
            return None
        a = np.array(q)
        t = a[:, 0] - a[:, 0].mean()
        if t[-1] - t[0] < 0.5 * self.rule.window_s:
            return None
        denom = float(t @ t)
        vx = float(t @ (a[:, 1] - a[:, 1].mean())) / denom
        vy = float(t @ (a[:, 2] - a[:, 2].mean())) / denom
        return float(np.hypot(vx, vy))

    def is_moving(self, track_id: int) -> bool:
        """True when :meth:`speed` is known and at least the rule's ``min_speed_mps``."""
        s = self.speed(track_id)
        return s is not None and s >= self.rule.min_speed_mps
