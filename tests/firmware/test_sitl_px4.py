"""Real PX4 (SIH quadrotor) SITL firmware flown by the mavlink backend through the whole runtime (marker ``sitl``); the
cases and fixtures are in :mod:`tests.firmware.sitl_cases`, each scenario in its own loopback-only network namespace."""
from __future__ import annotations

import pytest

from tests.firmware import sitl
from tests.conftest import needs_sitl
from tests.firmware.sitl_cases import *  # noqa: F401,F403 - the shared cases and fixtures
from tests.firmware.sitl_cases import _survey_done

AUTOPILOT = "px4"
pytestmark = [*SITL_MARKS, needs_sitl]  # no firmware or namespace: skipped, failed in CI

# PX4 runs its default parameters plus only what our backend sets (no EKF2 tuning: see tests/firmware/sitl.py MAX_SPEED for
# why its robots are limited to 2 m/s: stock SIH flies up to 0.5 m/s faster than its estimate, p99).
# A case listed here runs as a non-strict xfail.
# Three PX4 SIH behind one MAVProxy output port pass since 2026-11-23 (evening; twice, once beside two CPU burners at
# load average 7.4): the vehicles connect, fly and land; the check of the firmware's height at the end is
# ArduCopter's only (PX4's relative_alt drifts and jumps at the disarm, see sitl_cases.py).
KNOWN_GAPS: set[str] = set()


def test_a_limit_stock_px4_cannot_hold_is_reported(session):
    """The farm survey's first leg at its own max_speed 0.5 m/s on stock PX4 SIH: the backend's in-flight margin (GNSS speed
    minus the estimate's, p99) leaves no limit above PX4's floor (0.25 m/s) within 0.55 m/s, so it reports
    ``speed_limit_unholdable`` once and the summary says so. SIH's own ground truth (HIL_STATE_QUATERNION against
    the estimate, GLOBAL_POSITION_INT, airborne) shows the gap the margin is for: the vehicle flew more than 0.2 m/s
    faster than its estimate at the 99th percentile (0.29-0.59 m/s in runs so far). Whether that breaks 0.55 m/s
    in a given flight varies with it (the fastest true second 0.51-0.74 m/s); a report of unholdable in a flight
    that happened to stay under is the safe side."""
    import numpy as np

    run = session["slow"]
    bad = [e for e in events(run["rec"]) if e["event"] == "speed_limit_unholdable"]
    assert len(bad) == 1, [e["event"] for e in events(run["rec"])][-40:]
    # unholdable means 0.55 - margin < 0.25, i.e. a margin above 0.3 (0.3 at the event's 3 decimals in one run)
    assert bad[0]["max_speed"] == 0.5 and bad[0]["margin_mps"] >= 0.3, bad
    assert "speed limit NOT holdable" in run["out"], run["out"][-2000:]
    truth, est = np.array(run["truth"]["truth"]), np.array(run["truth"]["estimate"])
    assert len(truth) > 500 and len(est) > 500, (len(truth), len(est))
    k = np.clip(np.searchsorted(truth[:, 0], est[:, 0]), 1, len(truth) - 1)
    near = np.abs(truth[k, 0] - est[:, 0]) < 0.05
    airborne = est[:, 2] > 0.5
    over = truth[k, 1][near & airborne] - est[:, 1][near & airborne]
    p99 = float(np.percentile(over, 99))
    print(f"px4 slow: backend margin {bad[0]['margin_mps']} m/s over {bad[0]['samples']} samples; ground truth p99 "
          f"{p99:.3f} m/s over {len(over)} samples")
    assert p99 > 0.2, p99


def test_the_autopilots_own_failsafe_is_respected(session, autopilot):
    """PX4's own failsafe while AeroDaaS runs (PX4 only: ArduCopter has no failsafe for a GUIDED
    vehicle whose ground station stops, FS_GCS_ENABLE 0): our drone actor is frozen for 3 s wall in OFFBOARD
    flight, so our setpoint stream stops and PX4 leaves OFFBOARD after COM_OF_LOSS_T (its offboard-loss failsafe,
    default parameters). From the firmware's own HEARTBEATs: once it left OFFBOARD it never went back (with
    ``on_failsafe: end``, the default, nothing switches it back) and it landed and disarmed. From the recording: the
    failsafe was recorded with its mode and the mission's outcome is ``failsafe``, never a success."""
    run = session["failsafe"]
    fw = run["firmware"]
    assert fw.get("frozen"), run["out"][-2000:]
    modes = [m for _, m, armed in fw["modes"] if armed]
    assert "OFFBOARD" in modes, fw["modes"]
    after = modes[modes.index("OFFBOARD"):]
    left = next((i for i, m in enumerate(after) if m != "OFFBOARD"), None)
    assert left is not None, fw["modes"]                                 # the firmware left OFFBOARD by itself
    assert "OFFBOARD" not in after[left:], fw["modes"]                   # ... and we never took it back
    assert fw.get("landed"), fw["modes"]                                 # it flew its failsafe to the ground
    rec = run["rec"]
    ev = events(rec)
    fs = [e for e in ev if e["event"] == "autopilot_failsafe"]
    assert fs, [e["event"] for e in ev][-30:]
    results = [m for _, m in rec.get("/mission/result", [])]
    assert results and results[-1]["outcome"] == "failsafe", results
    assert run["rc"] != 0, run["out"][-2000:]                            # a failsafe is no success
    print(f"{autopilot} failsafe: firmware modes {[m for _, m, _ in fw['modes']]}, recorded {fs[0].get('mode')}")


def test_a_px4_rebooted_with_its_last_mission_flies_the_new_one(session):
    """The farm survey as an autopilot mission on the PX4 that flew it before, rebooted with its storage: the
    firmware reports the stored mission's last item after the new upload, which is no progress of the new one.
    Every corner reached and held (from the firmware's positions), the drone's own mission reports from the first
    item on, and the survey's waypoints reported reached where the vehicle was within 2 m of them (PX4's default
    acceptance radius, NAV_ACC_RAD)."""
    run = session["auto_again"]
    _survey_done(run, "auto_again", "px4")
    ev = events(run["rec"])
    current = [e["item"] for e in ev if e["event"] == "mission_current"]
    assert current and current[0] == 1 and current == sorted(current), current
    reached = [e for e in ev if e["event"] == "waypoint_reached"]
    # within PX4's own default acceptance radius (NAV_ACC_RAD 2 m); the stored mission's report made them 10-14 m
    assert len(reached) == 4 and all(e["error_m"] <= 2.0 for e in reached), reached


def test_a_mission_another_station_replaced_after_our_upload_is_not_started(session):
    """Our backend uploads a mission (read back, the same), then a second ground station uploads another on PX4's
    ground-station link: the start refuses before it sends anything, naming both plan ids, which are the firmware's
    own (its MISSION_ACKs' opaque_id and the MISSION_CURRENT the other station saw). The upload scenario after it
    (``aerodaas mission upload --start``, the same check) starts and flies."""
    got = session["plan_id"]
    ours, theirs = got.get("ours"), got.get("theirs", {})
    assert ours and theirs.get("ack_type") == 0 and theirs["ack_id"] not in (0, ours), got
    assert theirs["current_id"] == theirs["ack_id"], got  # the firmware reports the other station's mission
    assert got["start"].endswith(f"the vehicle reports mission id {theirs['ack_id']}, not {ours}, the id it gave the "
                                 f"mission uploaded: another mission replaced it; not started (upload the mission "
                                 f"again)"), got
