"""Three vehicles on one link each with its own key, on real ArduCopter SITL (marker ``sitl``): three
firmware instances (system ids 1-3) each send their SERIAL2 to the same UDP port, as three vehicles share one
telemetry radio; each is provisioned with its own key over its own SERIAL0 (the cable: ``aerodaas mavlink signing
setup``), and the three robots of tests/firmware/sitl_fleet_app.py name that one port with their own ``target_system`` and
key file. SERIAL2 is channel 2, where ArduPilot takes only correctly signed packets (GCS_Signing.cpp), so each
vehicle flies only on the messages signed with its own key, and ignores those signed for the others, which reach it
on the shared port too: the fleet flying shows each message went out signed with the key of the vehicle it was for.
(A key the vehicle does not hold fails before take-off: tests/firmware/test_sitl_signing.py. The same fleet with the keys
passed round, every robot refused with exit 2, passed once on 2026-11-26 and was left out: a minute of Ray start
and connect timeouts per CI run for what that test shows.)"""
from __future__ import annotations

import pytest

from tests.firmware import sitl
from tests.conftest import needs_sitl
from tests.firmware.sitl_cases import _within
from tests.firmware.test_sitl_signing import _key

pytestmark = [pytest.mark.sitl, needs_sitl]

#: the UDP port the three vehicles' SERIAL2 send to (the shared "radio")
SHARED_PORT = 14700
N = 3


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> dict:
    """The three vehicles started, provisioned one by one, then the fleet flown: each step's (exit code, output)
    and the recording."""
    d = tmp_path_factory.mktemp("sitl_signing_fleet")
    keys = [_key(d / f"drone{i + 1}.key") for i in range(N)]
    cfg = sitl.mavlink_env("ardupilot", sitl.FARM_ENV, n=N)
    for i, r in enumerate(cfg["robots"]):
        r["mavlink"].update(connection=f"udpin:127.0.0.1:{SHARED_PORT}", target_system=i + 1,
                            signing_key_file=keys[i])
    env = sitl._write_env(d / "fleet.json", sitl.small_cameras(cfg))  # noqa: SLF001 - the SITL helpers' own
    ns = d / "ns"
    ns.mkdir()
    setups = [" ".join([*map(str, sitl.AERODAAS), "mavlink", "signing", "setup", "--connection",
                        sitl.connection("ardupilot", i), "--key-file", keys[i], "--target-system", str(i + 1),
                        "--secure-link", "--timeout", "120"]) for i in range(N)]
    steps = [*setups,
             sitl.aerodaas_run(sitl.FLEET_APP, env, d / "fleet.mcap", hold_radius_m=sitl.HOLD_RADIUS["ardupilot"])]
    # each vehicle in a directory of its own (its storage, eeprom.bin, holds its key), its SERIAL2 sent to the shared
    # port as well
    sitl.run_in_namespace("ardupilot", ns, steps, n=N, sysids=True, own_dirs=True,
                          extra=f"--serial2 udpclient:127.0.0.1:{SHARED_PORT}", timeout_s=1500)
    return {"steps": [sitl.step_result(ns, k) for k in range(len(steps))],
            "rec": sitl._read_or_note(d / "fleet.mcap")}  # noqa: SLF001


def test_three_vehicles_with_their_own_keys_fly_on_one_link(fleet):
    """Each vehicle provisioned (setup exit 0, checked by a signed round trip with its key); the fleet exits 0 and
    each robot, connected to the system id it names, reached both of its waypoints and landed (its firmware's
    telemetry in the recording); no message of any vehicle was refused as unsigned or wrongly signed."""
    from aerodaas.recording.metrics import waypoint_visits

    for k in range(N):
        rc, text = fleet["steps"][k]
        assert rc == 0 and f"system {k + 1} signs with the key" in text, (k + 1, text[-2000:])
    rc, text = fleet["steps"][N]
    assert rc == 0, text[-3000:]
    rec = fleet["rec"]
    r = _within("ardupilot")
    for k, rid in enumerate(["quadrotor_base", "quadrotor_base_1", "quadrotor_base_2"]):
        ev = sitl.events(rec, rid)
        connected = [e for e in ev if e["event"] == "connected"]
        assert connected and connected[0]["system"] == k + 1, (rid, connected)
        refused = [e for e in ev if e["event"] in ("link_unsigned", "link_bad_signature")]
        assert not refused, (rid, refused[:5])
        odo = sitl.odometry(rec, rid)
        visits = waypoint_visits(odo, [(3.0 * k, 3.0, 1.5), (3.0 * k, 8.0, 1.5)], r)
        assert all(v["closest_m"] <= r and v["time_within_s"] >= 2.5 for v in visits), (rid, visits)
        assert not odo[-1]["in_air"], rid

