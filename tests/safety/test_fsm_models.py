import math

import pytest
from pydantic import ValidationError

from aerodaas.navigation.fsm import TRANSITIONS, IllegalTransition, MissionFSM, MissionState
from aerodaas.model.types import AeroNavigation, CameraIntrinsics, GeoPoint, NavigationType, SchedulingType, Waypoint


def test_fsm_has_the_papers_13_states_plus_link_lost_and_rejects_illegal_transitions():
    assert len(MissionState) == 14 and MissionState.LINK_LOST in MissionState
    seen = []
    fsm = MissionFSM(lambda old, new, t: seen.append((old, new)))
    for s in ("PREFLIGHT", "ARMED", "TAKING_OFF", "HOVERING", "NAVIGATING", "WAYPOINT_HOLD", "LANDING", "LANDED"):
        fsm.transition(s)
    assert fsm.state == MissionState.LANDED and len(seen) == 8
    with pytest.raises(IllegalTransition, match="LANDED -> NAVIGATING"):
        fsm.transition("NAVIGATING")
    assert fsm.state == MissionState.LANDED  # unchanged
    # every state is reachable from IDLE through the table
    reach, frontier = {MissionState.IDLE}, [MissionState.IDLE]
    while frontier:
        for n in TRANSITIONS[frontier.pop()]:
            if n not in reach:
                reach.add(n)
                frontier.append(n)
    assert reach == set(MissionState)


def test_link_lost_resumes_the_previous_activity_and_never_skips_the_ground():
    fsm = MissionFSM()
    for s in ("PREFLIGHT", "ARMED", "TAKING_OFF", "HOVERING", "NAVIGATING", "LINK_LOST", "NAVIGATING"):
        fsm.transition(s)
    fsm.transition("LINK_LOST")
    fsm.transition("LANDED")  # it landed by itself (autopilot failsafe) while the link was down
    with pytest.raises(IllegalTransition):
        MissionFSM().transition("LINK_LOST")  # IDLE: nothing is flying, the link cannot be "lost" yet


@pytest.mark.parametrize("kwargs,field", [
    ({"x": math.nan}, "x"), ({"z": math.inf}, "z"), ({"hover_duration": -1}, "hover_duration"),
    ({"waypoint_type": "absolute", "x": 123.0}, "latitude"), ({"id": ""}, "id"),
])
def test_invalid_waypoints_name_the_field(kwargs, field):
    base = dict(id="wp1", x=1.0, y=2.0, z=3.0)
    base.update(kwargs)
    with pytest.raises(ValidationError) as e:
        Waypoint(**base)
    assert field in str(e.value)


def test_absolute_waypoint_converts_with_pymap3d():
    home = GeoPoint(lat=47.0, lon=8.0, alt=400.0)
    # 0.001 deg of latitude is ~111 m north
    wp = Waypoint(id="a", x=47.001, y=8.0, z=10.0, waypoint_type="absolute")
    e, n, u = wp.to_local(home)
    assert abs(e) < 0.01 and 110.0 < n < 112.0 and u == 10.0


def test_aeronavigation_positional_and_duplicate_ids():
    wps = [Waypoint(id="a", x=0, y=0, z=1), Waypoint(id="b", x=1, y=0, z=1)]
    nav = AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, SchedulingType.UNORDERED)
    assert nav.scheduling_type == SchedulingType.UNORDERED and len(nav.waypoints) == 2
    with pytest.raises(ValidationError, match="duplicate waypoint ids"):
        AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps + [Waypoint(id="a", x=5, y=5, z=1)])


def test_intrinsics_from_hfov():
    k = CameraIntrinsics.from_hfov(640, 480, 90.0)
    assert k.fx == pytest.approx(320.0) and k.cx == 320.0
    with pytest.raises(ValueError, match="hfov_deg"):
        CameraIntrinsics.from_hfov(640, 480, 190.0)
