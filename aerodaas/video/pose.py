"""The vehicle's pose at a frame's capture time, from the poses sampled on the run clock.

A stream frame arrives 20-300 ms after its capture while the drone moves (at 5 m/s, 0.5-1.5 m): geo-locating its
detections with the newest pose puts them that far off. :func:`pose_at` interpolates the pose at the capture time
between the samples around it; :func:`pose_sampled_at` also says which samples those were.
"""
from __future__ import annotations

from collections.abc import Sequence


def pose_at(poses: Sequence[tuple[float, tuple, float]], t: float) -> tuple[tuple, float, float]:
    """The pose at run time ``t`` (s) from ``poses`` = [(time s, position ENU m (x, y, z), yaw deg), ...] in time
    order: linear between the two samples around ``t`` (yaw along the shorter arc, result in [-180, 180)),
    the oldest/newest sample outside them. Returns (position, yaw deg, the time the pose is of: ``t`` when
    interpolated, else the sample's). An empty ``poses`` gives the origin at ``t``."""
    position, yaw, pose_t, _ = pose_sampled_at(poses, t)
    return position, yaw, pose_t


def pose_sampled_at(poses: Sequence[tuple[float, tuple, float]], t: float
                    ) -> tuple[tuple, float, float, tuple[float, ...]]:
    """:func:`pose_at`, and the run times (s) of the samples the pose came from: the two around ``t`` it was
    interpolated between, the one sample used outside them, or () for no samples. Returns (position ENU m, yaw
    deg, the time the pose is of, sample times) — what a frame's timing records so that a check of its pose tag
    can see which samples were used, not only the time it was asked for."""
    if not poses:
        return (0.0, 0.0, 0.0), 0.0, t, ()
    lo, hi, a = _bracket([p[0] for p in poses], t)
    if hi is None:  # outside the samples: the nearest one, and its time
        return tuple(poses[lo][1]), poses[lo][2], poses[lo][0], (poses[lo][0],)
    (t0, p0, y0), (t1, p1, y1) = poses[lo], poses[hi]
    dy = (y1 - y0 + 180.0) % 360.0 - 180.0
    pos = tuple(float(c0 + a * (c1 - c0)) for c0, c1 in zip(p0, p1))
    return pos, (y0 + a * dy + 180.0) % 360.0 - 180.0, t, (t0, t1)


def angles_at(samples: Sequence[tuple[float, tuple[float, ...]]], t: float) -> tuple[tuple[float, ...], float] | None:
    """Angles (degrees) at run time ``t`` (s) from ``samples`` = [(time s, (angle deg, ...)), ...] in time order —
    a gimbal's (roll, pitch, yaw) at a stream frame's capture time: each angle linear between the two samples
    around ``t`` along the shorter arc (result in [-180, 180)), the oldest/newest sample outside them. Returns
    (angles, the time they are of: ``t`` when interpolated, else the sample's); None for no samples."""
    if not samples:
        return None
    lo, hi, f = _bracket([smp[0] for smp in samples], t)
    if hi is None:  # outside the samples: the nearest one, and its time
        return tuple(samples[lo][1]), samples[lo][0]
    a0, a1 = samples[lo][1], samples[hi][1]
    return tuple((x0 + f * ((x1 - x0 + 180.0) % 360.0 - 180.0) + 180.0) % 360.0 - 180.0
                 for x0, x1 in zip(a0, a1)), t


def _bracket(times: Sequence[float], t: float) -> tuple[int, int | None, float]:
    """Where run time ``t`` (s) falls in the non-empty, ordered sample ``times``: (lo, hi, fraction of the way from
    ``times[lo]`` to ``times[hi]``), or (index of the oldest/newest sample, None, 0.0) outside them."""
    if t <= times[0]:
        return 0, None, 0.0
    if t >= times[-1]:
        return len(times) - 1, None, 0.0
    lo, hi = 0, len(times) - 1
    while hi - lo > 1:  # bisect: times[lo] <= t < times[hi]
        mid = (lo + hi) // 2
        if times[mid] <= t:
            lo = mid
        else:
            hi = mid
    t0, t1 = times[lo], times[hi]
    return lo, hi, (t - t0) / (t1 - t0) if t1 > t0 else 0.0
