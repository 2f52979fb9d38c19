"""Real ArduCopter SITL firmware flown by the mavlink backend through the whole runtime (marker ``sitl``); the
cases and fixtures are in :mod:`tests.firmware.sitl_cases`, each scenario in its own loopback-only network namespace."""
from __future__ import annotations

import pytest

from tests.conftest import needs_sitl
from tests.firmware.sitl_cases import *  # noqa: F401,F403 - the shared cases and fixtures

AUTOPILOT = "ardupilot"
pytestmark = [*SITL_MARKS, needs_sitl]  # no firmware or namespace: skipped, failed in CI
