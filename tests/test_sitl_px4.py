"""Real PX4 (SIH quadrotor) SITL firmware flown by the mavlink backend through the whole runtime (marker ``sitl``); the
cases and fixtures are in :mod:`tests.sitl_cases`, each scenario in its own loopback-only network namespace."""
from __future__ import annotations

import pytest

from . import sitl
from .sitl_cases import *  # noqa: F401,F403 - the shared cases and fixtures

AUTOPILOT = "px4"
_SKIP = sitl.namespace_skip_reason()
pytestmark = [pytest.mark.sitl, pytest.mark.skipif(_SKIP is not None, reason=_SKIP or "")]

# Known gaps on PX4 SIH, measured 2026-11-22 in three module runs (load average 5-20 on 2 cores; see the README).
# PX4 SIH's own velocity estimate is biased against its ground truth (HIL_STATE_QUATERNION) by up to +-0.6 m/s in
# flight, also under its own DO_REPOSITION: its velocity loop holds the estimate at MPC_XY_VEL_MAX (0.6 x max_speed
# = 0.3 m/s) while the vehicle drifts. So the reported speed peaks at 0.46-0.62 m/s (often in LAND and at
# touchdown) and the distance flown over 4 s at 0.51-0.72 m/s against 0.55 (each run passed in one or two of the
# three), and the estimated position wanders about +-0.5 m in a hold, so a 5 s hover within 0.5 m is missed at a
# corner or two (1.0-4.9 s) in most guided runs; the autopilot mission and the link loss (no odometry gap any
# more) passed in two and one of three runs. The fleet completed once (exit 0, 2/2 waypoints each, landed; speed
# 0.62); once Ray did not start, once an arm whose ACKs were all lost ended the run (now taken as done when the
# HEARTBEAT shows it armed). These run and report until fixed.
KNOWN_GAPS = {"test_farm_survey_from_a_cold_vehicle", "test_speed_stays_within_the_limit",
              "test_autopilot_mission_holds_and_reaches", "test_link_loss_by_stopping_the_firmware",
              "test_three_vehicle_fleet"}
