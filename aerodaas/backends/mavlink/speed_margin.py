"""The speed margin a vehicle's own estimator needs, measured in flight: how much faster the vehicle moves than its
estimate says, judged by its GNSS.

Why: an autopilot limits the speed of its *estimate* (PX4 ``MPC_XY_VEL_MAX``, ArduCopter ``WPNAV_SPEED``), so the
vehicle's true speed is the limit plus whatever its estimator gets wrong. On a well-tuned vehicle that is a few
cm/s; on stock PX4 SIH (EKF2's default IMU noise, far below what SIH simulates) it was 0.5 m/s at the 99th
percentile (2026-11-24: true minus estimated horizontal speed, against SIH's ground truth HIL_STATE_QUATERNION).
The receiver's own velocity is an independent measurement of the true one (GPS_RAW_INT ``vel``, SIH: within
0.05 m/s median, 0.12 m/s p90 of the truth), and GNSS minus estimated speed tracked the true overshoot closely in
the same flights (p99 0.54 against 0.50 m/s at ``max_speed`` 0.5; 0.47 against 0.49 at 2). So the backend keeps
the airborne samples of ``|v_gnss| - |v_estimate|`` and, once it has enough, lowers the vehicle's own limit until
limit + overshoot (p99) fits within ``max_speed`` + :data:`SPEED_TOLERANCE`; a vehicle whose overshoot leaves
no room is reported (``speed_limit_unholdable``), never silently flown as if it held.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

#: the speed limit's tolerance: flown speed within ``max_speed`` x (1 + this) (over 1 s windows)
SPEED_TOLERANCE = 0.10
#: airborne GNSS samples needed before the margin is used (10 s at speed at the backend's 5 Hz GPS_RAW_INT; 25 s
#: where the vehicle only streams it at 2 Hz, REQUEST_DATA_STREAM's EXTENDED_STATUS)
MIN_SAMPLES = 50
#: the samples kept (the last minute at 5 Hz): a margin follows the vehicle's recent flight
WINDOW = 300
#: the quantile of the overshoot the limit leaves room for
QUANTILE = 99.0
#: a lowered limit is applied only when it is at least this much (m/s) below the applied one
MIN_STEP_MPS = 0.05


@dataclass(frozen=True)
class SpeedCap:
    """The vehicle's own horizontal speed limit (m/s) for a robot's ``max_speed``: ``cap_mps`` to set, the
    estimator overshoot it leaves room for (``margin_mps``, p99 m/s over ``samples`` airborne GNSS samples; None
    before :data:`MIN_SAMPLES`), and whether ``cap_mps`` + that overshoot fits within ``max_speed`` x
    (1 + :data:`SPEED_TOLERANCE`) (``holdable``)."""

    cap_mps: float
    margin_mps: float | None
    samples: int
    holdable: bool


class EstimatorSpeedMargin:
    """Airborne samples of GNSS speed minus estimated speed (m/s, horizontal), the last :data:`WINDOW` of them.

    Feed it with :meth:`add` for every GPS_RAW_INT with a 3-D fix (its ``vel``, cm/s -> m/s) and the latest
    estimated velocity; read :meth:`cap`. Not thread-safe (the backend calls it under its lock)."""

    def __init__(self) -> None:
        self._d: deque[float] = deque(maxlen=WINDOW)

    def add(self, gnss_speed_mps: float, estimate_speed_mps: float) -> None:
        """One airborne sample: the GNSS ground speed and the estimate's horizontal speed, both m/s. A non-finite
        difference is ignored (never raises)."""
        d = float(gnss_speed_mps) - float(estimate_speed_mps)
        if math.isfinite(d):
            self._d.append(d)

    @property
    def samples(self) -> int:
        """How many samples are kept (at most :data:`WINDOW`)."""
        return len(self._d)

    def margin_mps(self) -> float | None:
        """The p99 of the samples (m/s, >= 0), None before :data:`MIN_SAMPLES`."""
        if len(self._d) < MIN_SAMPLES:
            return None
        return max(0.0, float(np.percentile(np.fromiter(self._d, float), QUANTILE)))

    def cap(self, max_speed: float, default_cap: float, floor: float) -> SpeedCap:
        """The limit for ``max_speed`` (all m/s): ``default_cap`` (the autopilot's measured rule, params.py), lowered
        to ``max_speed`` x (1 + tolerance) - margin when the measured margin needs it, never below ``floor``
        (params.py ``speed_floor``). Never raises."""
        margin = self.margin_mps()
        if margin is None:
            return SpeedCap(default_cap, None, len(self._d), True)
        need = max_speed * (1.0 + SPEED_TOLERANCE) - margin
        return SpeedCap(max(floor, min(default_cap, need)), round(margin, 3), len(self._d), need >= floor)
