"""MAVLink 2 signing on real ArduCopter SITL (marker ``sitl``), one firmware boot in a
loopback-only network namespace (tests/firmware/sitl.py) shared by the tests below, which only read what it produced.

The firmware's ports play the roles they have on a real vehicle (ArduPilot GCS_Signing.cpp
``accept_unsigned_callback`` always takes unsigned packets on channel 0, "assumed to be secure channel. This is USB"):
serial0 (``udpin:127.0.0.1:14550``, channel 0) is the cable: ``aerodaas mavlink signing setup`` provisions the key
there, and an observer watches the firmware's own telemetry there; serial1 (``udpin:127.0.0.1:14551``, channel 1)
is the radio our signed survey flies over, where the firmware takes only correctly signed packets; serial2
(``tcp:127.0.0.1:5763``, channel 2) is the attacker's way in (another ground station), and the attacker also writes
spoofed telemetry in the vehicle's name onto our backend's own port. Steps, in order, on one freshly booted vehicle:

0. control: unsigned, over serial2, a command and a parameter read are answered (the attacker's port works);
1. ``aerodaas mavlink signing setup`` (SETUP_SIGNING, checked by a signed round trip);
2. the farm survey signed over serial1; once the vehicle is armed and 1 m up, the attacker (another process, no
   key) sends a forced disarm, DO_FLIGHTTERMINATION, DO_SET_MODE LAND, PARAM_SET WPNAV_SPEED and a harmless
   command over serial2, and GLOBAL_POSITION_INT 100 m north, BATTERY_STATUS at 5 %, SYS_STATUS at 5 % and 1 V and
   a HEARTBEAT claiming disarmed in LAND (CRITICAL) onto our port;
3. the survey again with a key the vehicle does not hold: exit 2 before take-off.

(PX4 SITL: the shared build, PX4 main 02e73e3b6f of 2026-03-02, has no signing: see docs/security.md.)"""
from __future__ import annotations

import json
import math
import os
import shlex
import sys
from pathlib import Path

import pytest

from tests.firmware import sitl
from tests.conftest import needs_sitl
from tests.firmware.sitl_cases import _survey_done
from tests.firmware.sitl_signing_attack import EVIL, PROBE_CMD

pytestmark = [pytest.mark.sitl, needs_sitl]

#: ArduCopter SITL's serial2 (its default ``tcp:5763``): the attacker's way in
ATTACK_AT = "tcp:127.0.0.1:5763"
#: the refused-key run's connect timeout (vehicle-independent wall seconds, in its error message)
WRONG_KEY_TIMEOUT_S = 20
#: after the attack ends, the firmware is judged for this long (firmware seconds)
AFTER_ATTACK_S = 5.0


def _key(path: Path) -> str:
    path.write_text(os.urandom(32).hex() + "\n")
    os.chmod(path, 0o600)
    return str(path)


@pytest.fixture(scope="module")
def signed(tmp_path_factory) -> dict:
    """The steps of the module docstring on one ArduCopter SITL; returns the exit code and output of each, the
    probe's and the observer's JSON and the survey's recording."""
    d = tmp_path_factory.mktemp("sitl_signing")
    key, wrong = _key(d / "drone.key"), _key(d / "wrong.key")
    radio = sitl.monitor_connection("ardupilot")  # serial1: the link the survey flies over
    # the camera is not under test: sitl.small_cameras leaves the firmware its CPU
    env = sitl._write_env(d / "signed.json", sitl.small_cameras(sitl.mavlink_env(  # noqa: SLF001 - the SITL helpers'
        "ardupilot", sitl.FARM_ENV, connection=radio, signing_key_file=key, target_system=1)))
    env_wrong = sitl._write_env(d / "wrong.json", sitl.small_cameras(sitl.mavlink_env(  # noqa: SLF001
        "ardupilot", sitl.FARM_ENV, connection=radio, signing_key_file=wrong, target_system=1,
        connect_timeout_s=WRONG_KEY_TIMEOUT_S)))
    py, q = shlex.quote(sys.executable), lambda p: shlex.quote(str(p))
    helper = f"{py} -m tests.firmware.sitl_signing_attack"
    cable = sitl.connection("ardupilot")  # serial0
    setup = " ".join(shlex.quote(a) for a in [*sitl.AERODAAS, "mavlink", "signing", "setup", "--connection", cable,
                                               "--key-file", key, "--secure-link", "--timeout", "120"])
    spoof_at = radio.replace("udpin:", "udpout:")  # to our backend's port, as the firmware sends there
    watch = (f"( {helper} watch {cable} {ATTACK_AT} {spoof_at} {q(d / 'watch.json')} {q(d / 'stop')} "
             f"> {q(d / 'watch.log')} 2>&1 & ) ; ")
    steps = [f"{helper} probe {ATTACK_AT} {q(d / 'probe.json')}",
             setup,
             watch + sitl.survey_step("ardupilot", env, d / "signed.mcap"),
             sitl.survey_step("ardupilot", env_wrong, d / "wrong.mcap"),
             f"touch {q(d / 'stop')}; for k in $(seq 1 120); do [ -e {q(d / 'watch.json')} ] && break; sleep 0.5; done"]
    sitl.run_in_namespace("ardupilot", d / "ns", steps, timeout_s=1500)
    out = {k: sitl.step_result(d / "ns", k) for k in range(len(steps))}

    def _json(name: str) -> dict:
        return json.loads((d / name).read_text()) if (d / name).exists() else {}

    log = d / "watch.log"
    return {"steps": out, "probe": _json("probe.json"), "watch": _json("watch.json"),
            "watch_log": log.read_text(errors="replace")[-2000:] if log.exists() else "",
            "rec": sitl._read_or_note(d / "signed.mcap")}  # noqa: SLF001


def _attack(signed: dict) -> dict:
    att = signed["watch"].get("attack")
    assert att and "end" in att, (signed["watch"].get("timeline", [])[-5:], signed["watch_log"])
    assert att["rc"] == 0, att
    return att


def test_setup_signing_provisions_the_firmware(signed):
    """``aerodaas mavlink signing setup`` exits 0 (its signed round trip checked); before it the firmware's
    HEARTBEATs were unsigned and the attacker's port took unsigned messages (the control), after it every
    HEARTBEAT the firmware sends is signed."""
    rc, text = signed["steps"][0]
    probe = signed["probe"]
    assert rc == 0 and [PROBE_CMD[0], 0] in probe["acks"] and probe["params"], (probe, text[-2000:])
    assert probe["signed_heartbeats"] and not any(probe["signed_heartbeats"]), probe
    rc, text = signed["steps"][1]
    assert rc == 0, text[-3000:]
    assert "signs with the key" in text, text[-2000:]
    beats = signed["watch"]["timeline"]
    assert beats and all(b[4] for b in beats), [b for b in beats if not b[4]][:5]


def test_the_signed_survey_flies(signed):
    """The survey over the signature-checking serial1 (our signed commands taken by the firmware): exit 0, every
    corner reached and held, landed and disarmed (from the firmware's telemetry in the recording), and not one
    message of the vehicle refused as wrongly signed."""
    rc, text = signed["steps"][2]
    run = {"rc": rc, "out": text, "rec": signed["rec"]}
    _survey_done(run, "signed", "ardupilot")
    names = [e["event"] for e in sitl.events(signed["rec"])]
    assert "link_bad_signature" not in names, names


def test_unsigned_commands_and_param_set_from_another_process_are_refused(signed):
    """The attacker's unsigned forced disarm, flight termination, LAND and PARAM_SET over serial2, in flight: the
    firmware acknowledged none of its commands (not even the harmless one it answered before provisioning), and
    its own telemetry shows it armed, in its mode and in the air from the attack's start until 5 firmware seconds
    after its end; WPNAV_SPEED was never 1234 (in no PARAM_VALUE the attacker or the observer saw, nor read back
    after the attack; the firmware sends every port the PARAM_VALUE of a parameter our backend sets)."""
    att = _attack(signed)
    assert att["answers"]["acks"] == [] and EVIL not in att["answers"]["params"], att["answers"]
    tl = signed["watch"]["timeline"]
    window = [b for b in tl if att["start"] <= b[0] <= att["end"] + AFTER_ATTACK_S]
    assert window and window[-1][0] >= att["end"] + AFTER_ATTACK_S - 1.0, (att, tl[-3:])
    mode = window[0][2]
    bad = [b for b in window if not b[1] or b[2] != mode or b[3] < 0.5]
    assert not bad, bad[:5]
    assert mode == "GUIDED", mode
    w = signed["watch"]
    assert EVIL not in [v for _, v in w["params"]] and w["read_back"] and EVIL not in w["read_back"], w["params"]


def test_spoofed_telemetry_leaves_no_trace_in_the_recording(signed):
    """GLOBAL_POSITION_INT 100 m north, BATTERY_STATUS at 5 % (the battery the backend reads: the firmware sends
    BATTERY_STATUS), SYS_STATUS at 5 % and 1 V and a HEARTBEAT claiming disarmed in LAND written unsigned onto our
    port in the vehicle's name: dropped (``link_unsigned`` events naming each type), no recorded position more than
    20 m from home (every position sample the backend takes is recorded), no battery below 50 %, no voltage below
    2 V, no battery, failsafe or disarm event in flight (one arming, one disarming)."""
    _attack(signed)
    ev = sitl.events(signed["rec"])
    dropped = {e.get("message") for e in ev if e["event"] == "link_unsigned"}
    assert {"GLOBAL_POSITION_INT", "SYS_STATUS", "BATTERY_STATUS", "HEARTBEAT"} <= dropped, \
        [e for e in ev if e["event"] == "link_unsigned"]
    assert max(e["total"] for e in ev if e["event"] == "link_unsigned") >= 80  # 5 rounds of 4 x 4 messages
    names = {e["event"] for e in ev}
    assert not {"battery_low", "battery_critical", "failsafe_rtl", "autopilot_failsafe"} & names, names
    seq = [e["event"] for e in ev]
    assert seq.count("armed") == 1 and seq.count("disarmed") <= 1, [n for n in seq if "arm" in n]
    odo = sitl.odometry(signed["rec"])
    assert max(math.hypot(*o["position"][:2]) for o in odo) < 20.0
    batt = [o["battery_pct"] for o in odo if o.get("battery_pct") is not None]
    assert batt and min(batt) > 50.0, min(batt or [None])
    volts = [o["battery_voltage"] for o in odo if o.get("battery_voltage")]
    assert volts and min(volts) > 2.0, min(volts or [None])


def test_a_key_the_vehicle_does_not_hold_fails_before_take_off_with_exit_2(signed):
    """The survey with another key: exit 2 with the clear error, and the firmware (its own telemetry) never armed
    again after the signed survey landed."""
    rc, text = signed["steps"][3]
    assert rc == 2, text[-3000:]
    assert f"no correctly signed heartbeat from system 1 within {WRONG_KEY_TIMEOUT_S} s" in text, text[-3000:]
    tl = signed["watch"]["timeline"]
    armed = [i for i, b in enumerate(tl) if b[1]]
    assert armed == list(range(armed[0], armed[-1] + 1)), "armed more than once"  # the signed survey's flight only
    assert len(tl) - armed[-1] > 10, (armed[-1], len(tl))  # watched on through the refused run
