"""The MAVLink emulator against the real firmware: the same scripted ground-station sequence
(:mod:`aerodaas.emulators.mavlink.trace`: connect, arm from cold, take off, a 2-waypoint AUTO mission with holds,
RTL, land) flown on ArduCopter SITL and PX4 SIH (../shared/sitl, each in a private network namespace with only
loopback, created here) and on our emulator, and the normalised traces compared: mode and arm acknowledgements,
pre-arm refusals, reached events, speeds, parameters. The differences that remain are docs/backends.md's
"Emulator vs firmware" table; each is allowed here by name (``ALLOWED``) and nowhere else.

The emulator runs with the firmware's boot timing (GPS fix and EKF position estimate late, as observed) so that
the cold-arm refusals show; its defaults are shorter so that the other tests stay fast."""
from __future__ import annotations

import inspect
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from aerodaas.emulators.mavlink.trace import run_trace, summarise, trace_emulator

from tests.conftest import skip_or_fail
from tests.firmware.sitl import FIRMWARE_NICE

pytestmark = pytest.mark.sitl

SITL = Path(os.environ.get("AERODAAS_SITL_DIR", Path(__file__).resolve().parents[3] / "shared" / "sitl"))
SPEEDUP = 10
WALL_LIMIT_S = 150.0
#: emulator options that give the firmware's boot timing (vehicle seconds, from the traces): ArduCopter's origin
#: ~8 s and "EKF3 IMU0 is using GPS" ~29 s after boot; PX4 SIH is ready before its API link is up
EMULATOR = {"ardupilot": {"gps_lock_s": 8.0, "ekf_gps_s": 20.0}, "px4": {"gps_lock_s": 0.3, "ekf_gps_s": 0.2}}

AP_SCRIPT = """
ip link set lo up
cd "$WORK"
"$SITL/arducopter/arducopter" --model + --speedup {speedup} -I0 -w --defaults "$SITL/arducopter/copter.parm" \\
    --home 47.397742,8.545594,488,0 --serial0 udpclient:127.0.0.1:14550 > sitl.log 2>&1 &
P=$!
"$PY" -m aerodaas.emulators.mavlink.trace udpin:127.0.0.1:14550 --autopilot ardupilot --out trace.json \\
    --wall-limit {wall}
kill $P; wait $P 2>/dev/null; true
"""
# PX4 keeps its server socket and lock in /tmp (px4-sock-N): a private /tmp (mount namespace; the work directory,
# which may be under /tmp, is bound to /mnt first) keeps parallel runs apart; the px4-* command aliases must be
# symlinks to px4 (the shared tree holds them as plain files)
PX4_SCRIPT = """
ip link set lo up
mount --make-rprivate / && mount --bind "$WORK" /mnt && mount -t tmpfs tmpfs /tmp
B=$(mktemp -d); W=$(mktemp -d); cd /mnt
for f in "$SITL"/px4/bin/px4-*; do n=$(basename "$f"); case "$n" in *.sh) cp "$f" "$B/";; *) ln -s "$SITL/px4/bin/px4" "$B/$n";; esac; done
PATH="$B:$PATH" PX4_SIM_MODEL=sihsim_quadx PX4_SIMULATOR=sihsim HEADLESS=1 PX4_SIM_SPEED_FACTOR={speedup} \\
    PX4_HOME_LAT=13.0213 PX4_HOME_LON=77.5671 PX4_HOME_ALT=920 nice -n {nice} "$SITL/px4/bin/px4" -d "$SITL/px4/etc" \\
    -w "$W" \\
    > sitl.log 2>&1 &
P=$!
"$PY" -m aerodaas.emulators.mavlink.trace udpin:127.0.0.1:14540 --autopilot px4 --out trace.json --wall-limit {wall}
kill $P; wait $P 2>/dev/null; true
"""

#: differences that remain (docs/backends.md, "Emulator vs firmware"): summary key -> reason
ALLOWED = {
    "ardupilot": {
        "cold_arm": "the first GUIDED arm meets the boot at a different stage (origin set or not)",
        "armable_after_s": "boot timing follows the firmware's within a few seconds, not exactly",
        "modes": "before arming the HEARTBEAT may or may not catch the short STABILIZE/GUIDED phases",
        "leg_max_speed": "the emulator accelerates at WPNAV_ACCEL without ArduPilot's S-curve jerk limit (within "
                         "25 %)",
        "reached_first_after_arrival_s": "ArduCopter's S-curve settles ~1-2.5 s before the hold starts (2.01 and "
                                         "2.51 s seen in full-suite runs)",
        "refusal_texts": "'Arm: Gyros/Accels inconsistent' (SITL boot artefact) not emulated",
    },
    "px4": {
        "modes": "PX4 SIH boots in AUTO.LOITER (no RC); the emulator in MANUAL (a vehicle with RC)",
        "cold_arm": "PX4 SIH is armable before its API link is up at this speed-up; the emulator nearly so",
        "refusal_texts": "PX4 sends no STATUSTEXT on its API link (14540); the emulator sends the GCS link's texts",
        "armable_after_s": "boot timing follows the firmware's within a few seconds, not exactly",
        "leg_max_speed": "the emulator's acceleration profile is simpler than PX4's jerk-limited one",
        "reached_count": "PX4 repeats MISSION_ITEM_REACHED while the trace listens; how many arrive depends on when "
                         "the next leg ends (>= 2 in both)",
        "reached_first_after_arrival_s": "the hold starts inside the acceptance radius, 0.4-2.5 s before the 1 m "
                                         "arrival in the runs seen",
        "home_alt_drift_m": "PX4's home correction follows its baro/GPS disagreement; the emulator's is a bounded "
                            "random walk",
    },
}


def _namespace_ok() -> str | None:
    if not sys.platform.startswith("linux") or shutil.which("unshare") is None or shutil.which("ip") is None:
        return "needs Linux with unshare and ip (util-linux, iproute2)"
    r = subprocess.run(["unshare", "-n", "-m", "true"], capture_output=True)
    if r.returncode != 0:
        return f"cannot create a network namespace here: {r.stderr.decode(errors='replace').strip()}"
    return None


def _firmware_trace(autopilot: str, tmp_path: Path) -> dict:
    exe = SITL / ("arducopter/arducopter" if autopilot == "ardupilot" else "px4/bin/px4")
    if not exe.exists():
        skip_or_fail(f"no firmware at {exe} (set AERODAAS_SITL_DIR)")
    why = _namespace_ok()
    if why:
        skip_or_fail(why)
    script = (AP_SCRIPT if autopilot == "ardupilot" else PX4_SCRIPT).format(speedup=SPEEDUP, wall=WALL_LIMIT_S,
                                                                             nice=FIRMWARE_NICE)
    env = {**os.environ, "SITL": str(SITL), "WORK": str(tmp_path), "PY": sys.executable,
           "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    r = subprocess.run(["unshare", "-n", "-m", "bash", "-c", textwrap.dedent(script)], env=env,
                       capture_output=True, timeout=WALL_LIMIT_S + 60)
    out = tmp_path / "trace.json"
    assert out.exists(), (r.returncode, r.stderr.decode(errors="replace")[-2000:],
                          (tmp_path / "sitl.log").read_text(errors="replace")[-2000:])
    return json.loads(out.read_text())


def _check_firmware_facts(autopilot: str, fw: dict) -> None:
    """What the firmware must show for the comparison to mean anything (and what the emulator copies)."""
    assert fw["ok"], fw
    assert fw["leg_max_speed"][0] > 3.0  # its own default speed until told
    assert fw["leg_max_speed"][1] is None or fw["leg_max_speed"][1] <= 2.0 * 1.1  # then the PARAM_SET speed
    if autopilot == "ardupilot":
        assert fw["refusal_results"] == ["FAILED"] and "Arm: Need Position Estimate" in fw["refusal_texts"]
        assert fw["change_speed_minus2"] == "DENIED" and fw["mission_requests"] == ["MISSION_REQUEST"]
        assert fw["params"]["WPNAV_SPEED"] == 1000.0 and fw["reached_count"] == [1, 1]
    else:
        assert fw["change_speed_minus2"] == "ACCEPTED" and fw["mission_requests"] == ["MISSION_REQUEST_INT"]
        assert fw["params"]["MPC_XY_CRUISE"] == 5.0 and min(fw["reached_count"]) >= 2


def _compare(autopilot: str, fw: dict, emu: dict) -> None:
    allowed = ALLOWED[autopilot]
    differ = sorted(k for k in fw if fw[k] != emu[k] and k not in allowed)
    assert not differ, {k: (fw[k], emu[k]) for k in differ}
    # the allowed differences stay within their stated bounds
    for f, e in zip(fw["leg_max_speed"], emu["leg_max_speed"]):  # None: parameter set after the leg (load)
        assert f is None or e is None or 0.75 * f <= e <= 1.25 * f + 0.05, (fw["leg_max_speed"],
                                                                            emu["leg_max_speed"])
    assert emu["leg_max_speed"][0] > 3.0  # its own default, not a robot's limit
    assert emu["leg_max_speed"][1] is None or emu["leg_max_speed"][1] <= 2.0 * 1.1  # the PARAM_SET speed
    hold = inspect.signature(run_trace).parameters["hold"].default  # s at each waypoint (both traces use it)
    # the firmware reports an item reached at the end of its hold, which starts once inside its acceptance radius:
    # where in the approach that is varies (the trace's arrival is the first position within 1 m). Measured: PX4 SIH
    # 2.06-2.62 s after arrival, and 0.52 s once on the slow second leg beside load in CI; ArduCopter 4.5-5.0 s (its
    # S-curve settles 1.5-2.5 s before the hold starts: unmodelled, ALLOWED above). The emulator: PX4 2.23-2.61 s,
    # ArduCopter 2.5-3.0 s.
    fw_reached, emu_reached = fw["reached_first_after_arrival_s"], emu["reached_first_after_arrival_s"]
    # each item reported (when, relative to the trace's arrival, is the firmware's), one after most of its hold
    assert None not in fw_reached and max(fw_reached) >= hold / 2, fw_reached
    for e in emu_reached:
        # the emulator reports after (most of) its hold, never on arrival (its old behaviour, e ~ 0), and not
        # noticeably after the firmware did in the same run
        assert e is not None and hold / 2 <= e <= max(fw_reached) + 1.0, (fw_reached, emu_reached)
    assert min(emu["reached_count"]) >= (1 if autopilot == "ardupilot" else 2)
    # the armed flight's modes and the mode after landing (ArduCopter: GUIDED, AUTO, RTL, stays RTL; PX4:
    # TAKEOFF, LOITER, MISSION, LOITER, RTL, then LOITER disarmed); before that only the cold arm differs
    k = 3 if autopilot == "ardupilot" else 5
    armed = [[m for m in t["modes"] if m.endswith("+armed")][-k:] + t["modes"][-1:] for t in (fw, emu)]
    assert armed[0] == armed[1], armed
    if autopilot == "ardupilot":
        assert emu["refusal_results"] == fw["refusal_results"]
        # every text the emulator refuses with is the firmware's: seen in this trace, or (a boot phase the trace's
        # arm attempts can miss on a loaded machine, such as AHRS waiting for home) a prearm text of its binary
        seen, said = set(fw["refusal_texts"]), set(emu["refusal_texts"])
        firmware = (SITL / "arducopter" / "arducopter").read_bytes()
        assert said & seen and all(t.removeprefix("Arm: ").encode() in firmware for t in said - seen), (said, seen)
    else:
        assert fw["home_alt_drift_m"] > 0.5 and 0.5 < emu["home_alt_drift_m"] <= 2.5


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_emulator_trace_matches_the_firmware(autopilot, tmp_path):
    fw = summarise(_firmware_trace(autopilot, tmp_path))
    _check_firmware_facts(autopilot, fw)
    emu_trace = trace_emulator(autopilot, speedup=SPEEDUP, wall_limit_s=WALL_LIMIT_S, emulator=EMULATOR[autopilot])
    emu = summarise(emu_trace)
    assert emu["ok"], emu_trace
    _compare(autopilot, fw, emu)
