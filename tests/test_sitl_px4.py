"""Real PX4 (SIH quadrotor) SITL firmware flown by the mavlink backend through the whole runtime (marker ``sitl``); the
cases and fixtures are in :mod:`tests.sitl_cases`, each scenario in its own loopback-only network namespace."""
from __future__ import annotations

import pytest

from . import sitl
from .sitl_cases import *  # noqa: F401,F403 - the shared cases and fixtures

AUTOPILOT = "px4"
_SKIP = sitl.namespace_skip_reason()
pytestmark = [pytest.mark.sitl, pytest.mark.skipif(_SKIP is not None, reason=_SKIP or "")]

# Known gaps on PX4 SIH, measured 2026-11-22 at load average ~28 on 2 cores (not fixed yet, see the README):
# OFFBOARD/AUTO.MISSION speed overshoots max_speed (0.58-0.87 m/s at 0.5, MPC_XY_VEL_MAX/CRUISE at 0.425),
# hover within 0.5 m for 5 s missed at some corners (SIH position hold), and under that load Ray itself failed
# to start in some runs (then the hover-height case fails too). These are expected to fail until fixed; they still
# run and report.
KNOWN_GAPS = {"test_farm_survey_from_a_cold_vehicle", "test_speed_stays_within_the_limit",
              "test_autopilot_mission_holds_and_reaches", "test_mission_upload_start",
              "test_link_loss_by_stopping_the_firmware", "test_three_vehicle_fleet",
              "test_hover_height_from_the_firmware_estimate"}  # passed (-0.13..+0.17 m) when Ray started
