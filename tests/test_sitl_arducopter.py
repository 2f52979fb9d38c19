"""Real ArduCopter SITL firmware flown by the mavlink backend through the whole runtime (marker ``sitl``); the
cases and fixtures are in :mod:`tests.sitl_cases`, each scenario in its own loopback-only network namespace."""
from __future__ import annotations

import pytest

from . import sitl
from .sitl_cases import *  # noqa: F401,F403 - the shared cases and fixtures

AUTOPILOT = "ardupilot"
_SKIP = sitl.namespace_skip_reason()
pytestmark = [pytest.mark.sitl, pytest.mark.skipif(_SKIP is not None, reason=_SKIP or "")]
