"""Real PX4 (SIH quadrotor) SITL firmware flown by the mavlink backend through the whole runtime (marker ``sitl``); the
cases and fixtures are in :mod:`tests.sitl_cases`, each scenario in its own loopback-only network namespace."""
from __future__ import annotations

import pytest

from . import sitl
from .sitl_cases import *  # noqa: F401,F403 - the shared cases and fixtures

AUTOPILOT = "px4"
_SKIP = sitl.namespace_skip_reason()
pytestmark = [pytest.mark.sitl, pytest.mark.skipif(_SKIP is not None, reason=_SKIP or "")]

# No known gaps on PX4 SIH any more (measured 2026-11-22, see the README): the farm survey, the autopilot mission,
# the link loss and the three-vehicle fleet, which failed here on SIH's velocity estimate (0.5 m hold offsets,
# 0.51-0.72 m/s flown against 0.55), pass since tests/sitl.py tells SIH's EKF2 its IMU noise (PX4_SIH_PARAMS) and
# the backend keeps PX4 at max_speed - 0.25 m/s (0.5 x here) with a 0.25 m setpoint lead (params.py, offboard.py).
# A case listed here runs as a non-strict xfail.
# Three PX4 SIH behind one MAVProxy output port pass since 2026-11-23 (evening; twice, once beside two CPU burners at
# load average 7.4): the vehicles connect, fly and land; the check of the firmware's height at the end is
# ArduCopter's only (PX4's relative_alt drifts and jumps at the disarm, see sitl_cases.py).
KNOWN_GAPS: set[str] = set()
