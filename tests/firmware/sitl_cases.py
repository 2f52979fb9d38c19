"""The real-firmware test cases and their module-scoped fixtures, shared by ``test_sitl_arducopter.py`` and
``test_sitl_px4.py`` (each sets ``AUTOPILOT`` and imports everything from here). Every assertion reads the recordings (``mcap`` reader) or the observer's
log; none is on wall-clock time."""
from __future__ import annotations

import math
import statistics

import pytest

from aerodaas.backends.mavlink.params import px4_speed_limit
from aerodaas.recording.metrics import waypoint_visits

from tests.firmware import sitl
from tests.firmware.sitl import (FARM_CORNERS, events, flown_speed, horizontal_speed, max_horizontal_speed, odometry,
                   sustained_speed)

#: each module's scenarios run in its first tests' fixtures (minutes of flight): beyond the suite's 600 s default.
#: The importing modules put these in their own ``pytestmark`` (a module's ``pytestmark`` replaces the one its
#: ``import *`` brought, and marks of this module never reach tests collected there): without it the seven PX4
#: single-vehicle scenarios ran under the 600 s default and timed out at load 30-35 (2026-11-26), ~3.3 min each
SITL_MARKS = [pytest.mark.sitl, pytest.mark.timeout(1800)]
pytestmark = SITL_MARKS


@pytest.fixture(scope="module")
def autopilot(request) -> str:
    """The importing test module's ``AUTOPILOT`` ("ardupilot" or "px4")."""
    return request.module.AUTOPILOT


@pytest.fixture(autouse=True)
def known_gap_xfail(request):
    """A case the importing module lists in ``KNOWN_GAPS`` is expected to fail (non-strict xfail, reason there)."""
    if request.node.originalname in getattr(request.module, "KNOWN_GAPS", ()):
        request.applymarker(pytest.mark.xfail(strict=False, reason=f"known gap on {request.module.AUTOPILOT}: "
                                                                   "see the module's comment and the README"))


@pytest.fixture(scope="module")
def session(autopilot, tmp_path_factory):
    """The single-vehicle scenarios (:func:`tests.firmware.sitl.single_vehicle_session`), flown once per module."""
    return sitl.single_vehicle_session(autopilot, tmp_path_factory.mktemp(f"sitl_{autopilot}"))


@pytest.fixture(scope="module")
def fleet(autopilot, tmp_path_factory):
    """Three firmware instances flying one app (:func:`tests.firmware.sitl.fleet_session`)."""
    return sitl.fleet_session(autopilot, tmp_path_factory.mktemp(f"sitl_{autopilot}_fleet"))

@pytest.fixture(scope="module")
def router_fleet(autopilot, tmp_path_factory):
    """Three firmware instances (system ids 1-3) behind one MAVProxy output port (:func:`tests.firmware.sitl.router_fleet_session`)."""
    return sitl.router_fleet_session(autopilot, tmp_path_factory.mktemp(f"sitl_{autopilot}_router"))


HOVER_S = 5.0  # the farm survey's hover_duration


def _states(rec: dict) -> list[tuple[float, str]]:
    return [(m["t"], m["state"]) for _, m in rec.get("/mission/state", [])]


def _holds(rec: dict) -> list[tuple[float, float]]:
    """(start, end) vehicle seconds of every WAYPOINT_HOLD in the stat-stream."""
    st = _states(rec)
    return [(t, st[i + 1][0]) for i, (t, s) in enumerate(st[:-1]) if s == "WAYPOINT_HOLD"]


def _within(autopilot: str) -> float:
    """How close (m, 3D) the SITL tests hold a vehicle to its waypoints: ArduCopter 0.5 m; PX4 the farthest point of
    its own reached region (:data:`tests.firmware.sitl.HOLD_RADIUS` horizontally, :data:`tests.firmware.sitl.PX4_ALT_RAD_M`
    vertically), since PX4 starts and keeps a hold anywhere in it (SIH's altitude estimate wanders up to 0.85 m in a
    hold, so the horizontal radius alone is no 3D bound)."""
    if autopilot == "px4":
        return math.hypot(sitl.HOLD_RADIUS["px4"], sitl.PX4_ALT_RAD_M)
    return max(0.5, sitl.HOLD_RADIUS[autopilot])


def _survey_done(run: dict, name: str, autopilot: str, hold_s: float = HOVER_S) -> list[dict]:
    """The survey's exit 0, every corner within :func:`_within` and ``hold_s`` vehicle seconds within that of it
    (from the recorded odometry), and the end LANDED on the ground."""
    rec = run["rec"]
    assert run["rc"] == 0, f"{name}: exit {run['rc']}\n{run['out'][-3000:]}"
    odo = odometry(rec)
    r = _within(autopilot)
    visits = waypoint_visits(odo, FARM_CORNERS, r)
    for v in visits:  # every corner reached and held there for the hover time
        assert v["closest_m"] <= r and v["time_within_s"] >= hold_s, (name, visits)
    assert _states(rec)[-1][1] == "LANDED", _states(rec)[-6:]
    assert not odo[-1]["in_air"]
    # recorded until the disarm (PX4's HEARTBEAT said armed for a moment after touchdown: the run used to end there)
    end = [e for e in events(rec) if e["event"] == "run_end"]
    assert end and end[-1]["how"].startswith("landed and disarmed") and not end[-1]["armed"], end
    return visits


def test_farm_survey_from_a_cold_vehicle(session, autopilot):
    """apps/farm_survey.py with a mavlink environment against a vehicle started seconds before (-w / fresh
    parameters): arms when the autopilot says it can, 4/4 waypoints within 0.5 m, >= 5 s at each, lands."""
    visits = _survey_done(session["guided"], "guided", autopilot)
    ev = events(session["guided"]["rec"])
    armed = [e for e in ev if e["event"] == "armed_after"]
    assert len(armed) == 1, [e for e in ev if e["event"].startswith("arm")]
    limits = [e for e in ev if e["event"] == "speed_limits"]
    assert limits, "the vehicle's speed limits were never set"
    print(f"{autopilot} guided: arming wait {armed[0]['wall_s']} s wall / {armed[0]['vehicle_s']} s vehicle, "
          f"visits {[round(v['closest_m'], 3) for v in visits]}")


def fastest_true_second(truth: dict, speedup: float) -> tuple[float, int, str]:
    """SIH's ground truth (:func:`tests.firmware.sitl_watchers.observe_truth`): the fastest mean horizontal speed
    (m/s) over 1 s of vehicle time while airborne, how many airborne samples, and why the observation does not cover
    the flight ("" when it does). Airborne: 0.5 m above the lowest sample (the observation ends 1 s after the
    disarm, on the ground, so an observer that started late still has its ground). 1 s of vehicle time is
    1 / ``speedup`` seconds of the observer's clock (HIL_STATE_QUATERNION carries no time stamp on SIH); windows with
    fewer than two samples (the firmware stopped) are left out. Covered: the observer heard the vehicle disarmed,
    armed and disarmed again, at least 100 airborne samples span at least half the armed interval, and at least half
    of them start a window that is measured."""
    import numpy as np

    t = np.array(truth["truth"])
    if not len(t):
        return 0.0, 0, "no ground-truth sample"
    air = t[t[:, 2] > t[:, 2].min() + 0.5]
    ends = np.searchsorted(air[:, 0], air[:, 0] + 1.0 / speedup)  # each window's first sample after it
    means = [float(air[i:j, 1].mean()) for i, j in enumerate(ends) if j < len(air) and j - i >= 2]
    armed, disarmed = truth.get("armed_s"), truth.get("disarmed_s")
    span = float(air[-1, 0] - air[0, 0]) if len(air) else 0.0
    why = ""
    if armed is None or disarmed is None:
        why = f"the observer saw no arm and disarm (armed_s {armed}, disarmed_s {disarmed})"
    elif len(air) < 100 or span < 0.5 * (disarmed - armed):
        why = (f"{len(air)} airborne of {len(t)} samples span {span:.1f} s of the {disarmed - armed:.1f} s armed "
               f"(first sample {t[0, 0] - armed:+.1f} s from the arm, lowest {t[:, 2].min():.2f} m AMSL)")
    elif len(means) < 0.5 * len(air):
        why = f"only {len(means)} of {len(air)} airborne samples start a 1 s window with two samples or more"
    return max(means, default=0.0), len(air), why


@pytest.mark.parametrize("run", ["guided", "auto", "linkloss"])
def test_speed_stays_within_the_limit(session, run, autopilot):
    """The robot's max_speed (sitl.MAX_SPEED: ArduCopter 0.5, PX4 2 m/s) + 10 %. ArduCopter: from the recorded
    odometry, the vehicle's own velocity and the distance flown over every >= 4 s of vehicle time (shorter windows
    measure the jitter between a position's arrival and its time stamp: up to one 0.1 s stream period). Stock PX4
    SIH: from SIH's own ground truth, the mean over every 1 s of vehicle time
    (:func:`fastest_true_second`), since its estimate is not what flew: EKF2 (its default noise, not SIH's) let the
    position estimate stall for 3.5 s and then caught up 2.6 m in 1.5 s, a reported 2.2-2.3 m/s at MPC_XY_VEL_MAX
    1.75 in AUTO while the truth's fastest second was 1.7 m/s."""
    rec = session[run]["rec"]
    odo = odometry(rec)
    assert len(odo) > 100, session[run]["out"][-2000:]
    v_reported = max_horizontal_speed(odo, from_positions=False)
    # distance over time needs one clock: leave out the link loss (the vehicle's clock stood still, ours ran on)
    ev = events(rec)
    lost = [e["t"] for e in ev if e["event"] == "link_lost"]
    back = [e["t"] for e in ev if e["event"] == "link_regained"]
    pieces = [odo] if not lost else [[o for o in odo if o["t"] < lost[0] - 2.0],
                                     [o for o in odo if o["t"] > (back[-1] if back else 1e9) + 3.0]]
    v_flown = max(flown_speed(p, 4.0) for p in pieces)
    limit = sitl.MAX_SPEED[autopilot]
    print(f"{autopilot} {run}: max speed reported {v_reported:.3f} m/s, flown over 4 s {v_flown:.3f} m/s "
          f"(limit {limit})")
    if autopilot == "px4":
        assert "truth" in session[run], f"px4 {run}: SIH's ground truth was not observed"
        v_true, n, uncovered = fastest_true_second(session[run]["truth"], sitl.SPEEDUP["px4"])
        print(f"px4 {run}: ground truth, fastest 1 s {v_true:.3f} m/s over {n} airborne samples")
        assert not uncovered, f"px4 {run}: SIH's ground truth does not cover the flight: {uncovered}"
        assert v_true <= limit * 1.1, v_true
    else:
        assert v_reported <= limit * 1.1 and v_flown <= limit * 1.1


def test_hover_height_from_the_firmware_estimate(session, autopilot):
    """While holding at each waypoint, the firmware's own altitude estimate (GLOBAL_POSITION_INT alt, AMSL) is at
    the commanded 1.5 m above the take-off point (the altitude reference fixed at arming): the holds' medians average
    within 0.3 m, every sample within 0.3 m (stock PX4 SIH, whose estimate wanders: 1.0 m)."""
    rec = session["guided"]["rec"]
    ref = [e["amsl_m"] for e in events(rec) if e["event"] == "altitude_reference"]
    assert ref, "no altitude reference"
    errs, medians = [], []
    for a, b in _holds(rec):
        hold = [o["geodetic"]["alt"] - ref[-1] - 1.5 for o in odometry(rec) if a + 1.0 <= o["t"] <= b]
        errs += hold
        medians += [statistics.median(hold)] if hold else []
    assert len(errs) > 50
    print(f"{autopilot}: hover height error {min(errs):+.3f} .. {max(errs):+.3f} m, per hold median "
          f"{[round(m, 3) for m in medians]}")
    # the height we command: the holds' medians average within 0.3 m (a wrong altitude reference, e.g. PX4's home
    # re-estimated after take-off, 0.5-0.6 m off in these runs, shifts every hold alike; PX4 SIH's estimate wanders
    # from hold to hold: one hold's median was -0.305 m with two CPU burners, their mean -0.135 m, 2026-11-24)
    assert abs(statistics.mean(medians)) <= 0.3, medians
    # stock PX4 SIH: its altitude estimate wanders as its horizontal one does (tests/firmware/sitl.py MAX_SPEED): within
    # -0.44 .. +0.31 m idle and with two CPU burners, -0.733 .. +0.394 m in the CI run of 2026-11-24 (with the EKF2
    # noise overrides the tests used to add: within 0.24 m)
    assert max(abs(e) for e in errs) <= (1.0 if autopilot == "px4" else 0.3)


def test_autopilot_mission_holds_and_reaches(session, autopilot):
    """use_autopilot_mission: the same survey uploaded (MISSION_ITEM_INT) and flown in AUTO / AUTO.MISSION: 4/4
    within the survey's radius; ArduCopter >= 5 s within 0.5 m at each, PX4 its own hold of each item >= 5 s by its
    own reports (below); the stat-stream's WAYPOINT_HOLD covers the hover (it starts on arrival, not when the
    autopilot's MISSION_ITEM_REACHED comes after the hold); one reached event per item."""
    # the autopilot flies the hold of its own mission: PX4 starts the item's hold time once its own reached check
    # passes (navigator mission_block.cpp is_mission_item_reached: horizontal distance within the item's acceptance
    # radius, 1 m here, and altitude within NAV_MC_ALT_RAD, 0.8 m by default, on its estimate) and sends
    # MISSION_ITEM_REACHED when the hold is over. How long its estimate then stays within a sphere of ours is PX4
    # SIH's wander, not the backend's doing (the backend sends nothing in AUTO.MISSION): 3.8-5.0 s of 5 within 0.5 m
    # (2026-11-24) and, in one CI run, 3.5 s within 1 m at one corner while the vehicle reached the next corner at
    # the same vehicle second as in a passing run (48.16 s). So PX4's hold is judged from its own telemetry: from
    # the first recorded sample inside its reached region to its MISSION_ITEM_REACHED, at least the uploaded hold
    # less half a second (a 10 Hz sample can come up to 0.3 s after its check passed)
    visits = _survey_done(session["auto"], "auto", autopilot, hold_s=0.0 if autopilot == "px4" else HOVER_S)
    rec = session["auto"]["rec"]
    holds = _holds(rec)
    assert len(holds) == 4, holds
    # each WAYPOINT_HOLD starts when the recorded position first comes within the arrival radius of its
    # corner, and ends when the autopilot says the hold is done (MISSION_ITEM_REACHED, after its hold time). How
    # long that is depends on the firmware: PX4 counts its hold from its own reached check (1 m, no settle), so with
    # two CPU burners its vehicle crawled from 1 m to 0.5 m at 0.4 m/s and our record of its 5 s hold was 2.08 s
    # (2026-11-24, PX4's own MISSION_ITEM_REACHED 2.04 s after our arrival); ArduCopter counts from within its
    # WPNAV_RADIUS and must show 4 s or more
    odo, done = [o for o in odometry(rec) if o["in_air"]], [e for e in events(rec)
                                                             if e["event"] == "mission_item_hold_done"]
    assert len(done) == 4, [(e["event"], e.get("item"), e.get("by")) for e in events(rec)]
    # from the take-off item's end on (the take-off climbs at the first corner's position); the backend's arrival
    # radius is the item's acceptance radius, for ArduPilot at most 0.5 m (aerodaas/backends/mavlink/mission.py)
    radius = sitl.HOLD_RADIUS[autopilot] if autopilot == "px4" else min(sitl.HOLD_RADIUS[autopilot], 0.5)
    takeoff = [e["t"] for e in events(rec) if e["event"] == "mission_item_reached" and e.get("by") == "autopilot"]
    assert takeoff, [e["event"] for e in events(rec)]
    after = min(takeoff)
    for (start, end), corner, d in zip(holds, FARM_CORNERS, done):
        arrived = next((o["t"] for o in odo if o["t"] > after and math.dist(o["position"][:2], corner[:2]) <= radius),
                       None)
        assert arrived is not None, (corner, after)
        # (the arrival sample itself may be one the 10 Hz recording skipped: up to a period, 0.1 s, plus jitter)
        assert arrived - 0.2 <= start <= arrived + 1.0 and start < d["t"] - 1.0, (corner, arrived, start, d)
        assert abs(end - d["t"]) <= 1.0, (corner, end, d)
        assert autopilot == "px4" or end - start >= HOVER_S - 1.0, (corner, start, end)
        if autopilot == "px4":  # PX4's own hold: from its reached region to its MISSION_ITEM_REACHED (see above)
            inside = next((o["t"] for o in odo if o["t"] >= after - 0.3
                           and abs(o["position"][2] - corner[2]) <= sitl.PX4_ALT_RAD_M
                           and math.dist(o["position"][:2], corner[:2]) <= sitl.HOLD_RADIUS["px4"]), None)
            assert inside is not None and d["t"] - inside >= HOVER_S - 0.5, (corner, inside, d, visits)
        after = end
    reached = [e["item"] for e in events(rec) if e["event"] == "mission_item_reached"]
    assert len(reached) == len(set(reached)), reached


#: PX4 counts a multicopter waypoint without an acceptance radius of its own (a mission file's param2 0) reached
#: within NAV_ACC_RAD horizontally (m): 2 for the SIH quadrotor (airframe 10040_sihsim_quadx sources
#: etc/init.d/rc.mc_defaults, ``param set-default NAV_ACC_RAD 2``); its hold there need not bring it closer
PX4_NAV_ACC_RAD_M = 2.0


def test_mission_upload_start(session, autopilot):
    """`aerodaas mission upload FILE --start --max-speed 2` on the landed vehicle: uploaded with a DO_CHANGE_SPEED 2 m/s
    inserted after the take-off (said; ArduCopter's whole seconds and centimetres said too), armed, flown by the
    autopilot at no more than that + 10 % (an observer on the link sees the vehicle reach both waypoints: within 1 m
    on ArduCopter, in 3D; on PX4 within its own reached check's radius, :data:`PX4_NAV_ACC_RAD_M`) and landed. The
    speed: the estimate's velocity on ArduCopter; on stock PX4 SIH, whose position estimate stalls and catches up
    (one run: 6 m in 2 s, 3.7 m/s, over 4 s 1.97 m/s), the distance the estimate moved over every >= 4 s of vehicle
    time (:func:`test_speed_stays_within_the_limit`). On PX4 this catches a runaway, not a missing cap: on these 6 m
    legs the vehicle never reaches its 5 m/s cruise (without ``--max-speed``: 2.47 m/s at most, 1.34 over 4 s); the
    cap itself is checked by the read-back (the vehicle holds the 5 items sent, the speed change among them)."""
    up = session["upload"]
    assert up["rc"] == 0, up["out"][-2000:]
    assert "inserted: DO_CHANGE_SPEED 2 m/s (--max-speed 2 m/s" in up["out"], up["out"][-2000:]
    assert "read back: the vehicle holds the 5 items as sent" in up["out"], up["out"][-2000:]
    if autopilot == "ardupilot":  # the first waypoint as ArduCopter stores it (AP_Mission): said, not refused
        for kept in ("param1 2.5 sent, 2 stored (ArduCopter keeps this time in whole seconds)",
                     "altitude 2.004 sent, 2 stored (ArduPilot keeps an altitude in whole centimetres)"):
            assert kept in up["out"], up["out"][-2000:]
    obs = session["observe"]["observed"]
    assert obs.get("armed") and obs.get("landed"), session["observe"]["out"][-2000:]
    pts = [(s[1], s[2], s[3]) for s in obs["samples"]]
    # PX4 judged horizontally, as its own reached check is: the observer never arms, so its height is PX4's
    # relative_alt, which drifts on SIH (see test_three_vehicles_behind_one_router_port)
    n, radius = (2, PX4_NAV_ACC_RAD_M) if autopilot == "px4" else (3, 1.0)
    for wp in ((0.0, 6.0, 2.0), (6.0, 6.0, 2.0)):
        closest = min(math.dist(p[:n], wp[:n]) for p in pts)
        assert closest < radius, (wp, closest)
    v = max(math.hypot(s[4], s[5]) for s in obs["samples"])
    flown = flown_speed([{"t": s[0], "position": s[1:4]} for s in obs["samples"]], 4.0)
    print(f"{autopilot} mission upload --start: max speed {v:.2f} m/s, flown over 4 s {flown:.2f} m/s (--max-speed 2)")
    assert (flown if autopilot == "px4" else v) <= 2.0 * 1.1


def test_geofence_refusal_through_the_safety_gate(session, autopilot):
    """The survey with a geofence exclusion circle around the (10, 10) corner: the safety gate refuses that
    waypoint when the application plans it, before anything starts (exit 2, the field named); nothing flew."""
    run = session["fence"]
    assert run["rc"] == 2, run["out"][-2000:]
    assert "geofence" in run["out"] and "exclusion circle" in run["out"], run["out"][-2000:]


def test_link_loss_by_stopping_the_firmware(session, autopilot):
    """The firmware process stopped for 6 s in flight (SIGSTOP/SIGCONT): LINK_LOST then recovery, odometry
    without a gap in vehicle time until the firmware went silent, then none (the last position is never
    repeated under new time stamps while nothing arrives; those repeats read as 3.69 m/s where the firmware flew
    1.87), and the survey still completes and lands."""
    rec = session["linkloss"]["rec"]
    ev = events(rec)
    names = [e["event"] for e in ev]
    assert "link_lost" in names and "link_regained" in names, (names, session["linkloss"]["out"][-2000:])
    assert "LINK_LOST" in [s for _, s in _states(rec)]
    lost_t = next(e["t"] for e in ev if e["event"] == "link_lost")
    everything = odometry(rec)
    odo = [o for o in everything if o["t"] <= lost_t]
    gaps = [b["t"] - a["t"] for a, b in zip(odo, odo[1:])]
    # 3 s of vehicle time = 0.6 s of wall time at 5x: a stall of the loaded machine, not the silence
    assert odo and max(gaps) < 3.0, (max(gaps), odo[-1]["t"], lost_t)
    # while silent, nothing was recorded: the next record after the last sample is the vehicle's first after the
    # silence, where its clock resumed (not judged against `link_regained`: the backend says that after a few
    # messages, 0.8-1.1 vehicle-s later at 5x, more on a loaded machine)
    assert "vehicle_clock_resumed" in names, names
    resumed_t = next(e["t"] for e in ev if e["event"] == "vehicle_clock_resumed")
    later = [o for o in everything if o["t"] > odo[-1]["t"]]
    assert later and later[0]["t"] >= resumed_t - 0.5, (odo[-1]["t"], later and later[0]["t"], resumed_t)
    _survey_done(session["linkloss"], "linkloss", autopilot)


def test_three_vehicle_fleet(fleet, autopilot):
    """Three firmware instances, one application: every vehicle flies both of its waypoints and lands."""
    assert fleet["rc"] == 0, fleet["out"][-3000:]
    rec = fleet["rec"]
    ids = ["quadrotor_base", "quadrotor_base_1", "quadrotor_base_2"]
    for k, rid in enumerate(ids):
        odo = odometry(rec, rid)
        r = _within(autopilot)
        visits = waypoint_visits(odo, [(3.0 * k, 3.0, 1.5), (3.0 * k, 8.0, 1.5)], r)
        assert all(v["closest_m"] <= r and v["time_within_s"] >= 2.5 for v in visits), (rid, visits)
        assert not odo[-1]["in_air"], rid
        # the limit held: the distance flown over every 4 s, and the reported velocity's median over every 1 s
        # (three firmware at 2x on a loaded CI machine reported one instant above 0.55 m/s once: EKF2's jolts
        # last 0.2-0.5 s, see aerodaas/backends/mavlink/params.py); the peaks are in the message
        flown = flown_speed(odo, 4.0)
        smooth = sustained_speed(odo, 1.0)
        peaks = sorted(((round(horizontal_speed(o), 3), round(o["t"], 1)) for o in odo), reverse=True)[:5]
        limit = sitl.MAX_SPEED[autopilot]
        assert flown <= limit * 1.1 and smooth <= limit * 1.1, (rid, flown, smooth, peaks)


def test_three_vehicles_behind_one_router_port(router_fleet, autopilot):
    """Three vehicles, system ids 1-3, one MAVProxy output port shared by the three robots (one socket in one drone
    actor): each flies its own survey (x = 0, 3, 6 m), lands and disarms, as each firmware's own telemetry (its
    serial1, followed by an independent observer) shows."""
    r = router_fleet
    assert r["rc"] == 0, r["out"][-3000:] + "\nMAVProxy:\n" + r["mavproxy"]
    for k, obs in enumerate(r["observed"]):
        assert obs.get("armed") and obs.get("landed") and obs.get("complete"), (
            k, {key: obs.get(key) for key in ("armed", "landed", "complete")})
        # away from where it stood (more than 1 m), not "above some relative_alt": PX4's relative_alt is no height
        # reference on SIH (one vehicle's drifted to -2.2 m in flight, so a height bound kept 133 of its 1,097
        # samples and lost its last leg: y peaked at 7.32 m among them, 8.06 m in all; run of 2026-11-24)
        x0, y0 = obs["samples"][0][1:3]
        flying = [s for s in obs["samples"] if math.hypot(s[1] - x0, s[2] - y0) > 1.0]
        assert flying, k
        # the firmware flew the survey of the robot with its system id (every other robot's waypoints are 3 m or more
        # from these): it came within _within of both of its waypoints (3k, 3) and (3k, 8). Judged by where it went,
        # not by where it spent most samples: the median x of the flying samples (the check before) counts the
        # transit from (0, 0), and in the CI run of 2026-11-27 (beside the cluster lane) vehicle 3's was under 5 m
        # (x 0.63-7.18). Idle, the closest approaches are 0.03-0.22 m (2026-11-27)
        reach = [min(math.hypot(s[1] - wx, s[2] - wy) for s in flying) for wx, wy in ((3.0 * k, 3.0), (3.0 * k, 8.0))]
        assert max(reach) <= _within(autopilot), (k, reach, min(s[1] for s in flying), max(s[1] for s in flying))
        if autopilot == "ardupilot":
            assert obs["samples"][-1][3] < 0.3, (k, obs["samples"][-1])
        # PX4: its disarm is the firmware's own landed verdict (we never force one, and Commander::disarm denies an
        # unforced disarm unless the land detector says landed: "Disarming denied: not landed", commander/
        # Commander.cpp); its relative_alt is no ground reference at the end: on SIH it drifted 0.6-0.9 m over the
        # 100 s flight and jumped by about 1 m between 0.1 s samples at the disarm (run of 2026-11-23)
    rec = r["rec"]
    for k, rid in enumerate(["quadrotor_base", "quadrotor_base_1", "quadrotor_base_2"]):
        connected = [e for e in events(rec, rid) if e.get("event") == "connected"]
        assert connected and connected[0]["system"] == k + 1, (rid, connected)
        visits = waypoint_visits(odometry(rec, rid), [(3.0 * k, 3.0, 1.5), (3.0 * k, 8.0, 1.5)], _within(autopilot))
        assert all(v["closest_m"] <= _within(autopilot) for v in visits), (rid, visits)


def test_recorded_speed_matches_the_firmware(router_fleet, autopilot):
    """Odometry once per vehicle sample, stamped with the firmware's time_boot_ms: the speed computed from the
    recorded positions and times matches what the firmware flew (its own positions and time_boot_ms) within 5 %
    over 1 s and 2 s windows (recordings repeated positions under new time stamps: 0.56-0.58 m/s where
    the firmware flew 0.51-0.52); in flight every recorded sample is one the vehicle sent, and every position
    sample that reached the router (MAVProxy's own log) is recorded at the odometry sensor's 10 Hz."""
    assert router_fleet["rc"] == 0, router_fleet["out"][-3000:]
    rec = router_fleet["rec"]
    for rid in ["quadrotor_base", "quadrotor_base_1", "quadrotor_base_2"]:
        odo = odometry(rec, rid)
        ts = [o["t"] for o in odo]
        assert all(b > a for a, b in zip(ts, ts[1:])), rid
        # the fastest 1 s (and 2 s) flown, from the recording and from the firmware's own GLOBAL_POSITION_INT
        # and time_boot_ms (a raw pymavlink observer on the vehicle's serial1): within 5 %
        k = ["quadrotor_base", "quadrotor_base_1", "quadrotor_base_2"].index(rid)
        fw = [{"t": s[0], "position": s[1:4]} for s in router_fleet["observed"][k]["samples"]]
        # the vehicle must have flown its legs for the comparison to mean anything: at least 30 % of its cruise
        # speed over the window (PX4 cruises at MPC_XY_VEL_MAX = px4_speed_limit(max_speed)). Idle, the vehicles
        # fly 1.3-1.6 m/s of PX4's 1.75 over 2 s; with two CPU burners PX4 SIH at 2x flew one at 0.99 (2026-11-24)
        cruise = px4_speed_limit(sitl.MAX_SPEED[autopilot]) if autopilot == "px4" else sitl.MAX_SPEED[autopilot]
        for window in (1.0, 2.0):
            ours, theirs = flown_speed(odo, window), flown_speed(fw, window)
            assert theirs > 0.3 * cruise and abs(ours / theirs - 1.0) <= 0.05, (rid, window, ours, theirs)
        # every sample that reached us is recorded (the CI run of 2026-11-24 recorded 1.265 m/s where the firmware
        # flew 1.434: holes of 0.5-1 s in flight, 4 s with two CPU burners, while the drone's clock thread waited).
        # Judged against what the router received (its tlog): with two CPU burners MAVProxy itself loses 18-23 % of
        # each PX4's onboard stream at its input (sequence numbers in its own log), and every hole in our recording
        # was one of those (2026-11-24)
        # (MAVProxy's tlog is what it received, before forwarding: a loss on its hop to our socket would show here,
        # with the namespace's UDP RcvbufErrors in the message)
        flying = [o["t"] for o in odo if o["in_air"]]
        assert len(flying) > 100, (rid, len(flying))
        matched, missing = sitl.unrecorded_samples([(o["t"], sitl.position_key(o)) for o in odo],
                                                   router_fleet["router_positions"].get(k + 1, []), 0.1,
                                                   within=(flying[0], flying[-1]))
        assert matched == 1.0, (rid, len(flying), matched)
        assert not missing, (rid, len(missing), missing[:10], router_fleet["udp"])
        # and never more than the odometry sensor's 10 Hz (one sample per slot, actors/drone/odometry.py)
        assert len(flying) <= 10.0 * (flying[-1] - flying[0]) * 1.02 + 3, (rid, len(flying), flying[-1] - flying[0])
