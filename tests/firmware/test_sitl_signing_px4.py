"""MAVLink 2 signing on PX4 SITL (marker ``sitl``): the shared PX4 build cannot sign, and our provisioning says so.

PX4 gained MAVLink 2 signing with PX4-Autopilot pull request 25284 (``src/modules/mavlink/mavlink_sign_control.cpp``:
SETUP_SIGNING stores the key, then every link signs and checks; docs.px4.io "MAVLink Message Signing"). The shared
build (``../shared/sitl/px4``, PX4 main 02e73e3b6f of 2026-03-02) predates it: its binary holds none of that
module's strings ("MAVLink signing key updated via SETUP_SIGNING"). On it, ``aerodaas mavlink signing setup`` must
fail (exit 1, no signed round trip) rather than claim a provisioned vehicle, and the firmware's own behaviour shows
why: after SETUP_SIGNING its HEARTBEATs still come unsigned and it still answers an unsigned command. When a PX4
build with signing is installed, this test fails: fly tests/firmware/test_sitl_signing.py's scenario on it instead."""
from __future__ import annotations

import json
import shlex
import sys

import pytest

from tests.firmware import sitl
from tests.conftest import needs_sitl
from tests.firmware.sitl_signing_attack import PROBE_CMD
from tests.firmware.test_sitl_signing import _key

pytestmark = [pytest.mark.sitl, needs_sitl]

SETUP_TIMEOUT_S = 30


def test_the_shared_px4_build_does_not_sign_and_setup_says_so(tmp_path):
    key = _key(tmp_path / "drone.key")
    setup = " ".join(shlex.quote(a) for a in [*sitl.AERODAAS, "mavlink", "signing", "setup", "--connection",
                                               sitl.connection("px4"), "--key-file", key, "--secure-link",
                                               "--timeout", str(SETUP_TIMEOUT_S)])
    probe = (f"{shlex.quote(sys.executable)} -m tests.firmware.sitl_signing_attack probe {sitl.monitor_connection('px4')} "
             f"{shlex.quote(str(tmp_path / 'probe.json'))} no")
    sitl.run_in_namespace("px4", tmp_path / "ns", [setup, probe], timeout_s=600)
    rc, text = sitl.step_result(tmp_path / "ns", 0)
    assert rc == 1, text[-3000:]
    assert "the signed round trip failed" in text and "no correctly signed heartbeat" in text, text[-3000:]
    rc, text = sitl.step_result(tmp_path / "ns", 1)
    got = json.loads((tmp_path / "probe.json").read_text())
    # after SETUP_SIGNING: an unsigned command still answered, every HEARTBEAT still unsigned
    assert rc == 0 and [PROBE_CMD[0], 0] in got["acks"], (got, text[-2000:])
    assert got["signed_heartbeats"] and not any(got["signed_heartbeats"]), got
