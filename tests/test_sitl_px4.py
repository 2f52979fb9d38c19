"""Real PX4 (SIH quadrotor) SITL firmware flown by the mavlink backend through the whole runtime (marker ``sitl``); the
cases and fixtures are in :mod:`tests.sitl_cases`, each scenario in its own loopback-only network namespace."""
from __future__ import annotations

import pytest

from . import sitl
from .sitl_cases import *  # noqa: F401,F403 - the shared cases and fixtures

AUTOPILOT = "px4"
_SKIP = sitl.namespace_skip_reason()
pytestmark = [pytest.mark.sitl, pytest.mark.skipif(_SKIP is not None, reason=_SKIP or "")]

# PX4 runs its default parameters plus only what our backend sets (no EKF2 tuning: see tests/sitl.py MAX_SPEED for
# why its robots are limited to 2 m/s: stock SIH flies up to 0.5 m/s faster than its estimate, p99).
# A case listed here runs as a non-strict xfail.
# Three PX4 SIH behind one MAVProxy output port pass since 2026-11-23 (evening; twice, once beside two CPU burners at
# load average 7.4): the vehicles connect, fly and land; the check of the firmware's height at the end is
# ArduCopter's only (PX4's relative_alt drifts and jumps at the disarm, see sitl_cases.py).
KNOWN_GAPS: set[str] = set()
