"""What ``aerodaas mission upload`` sends and checks: speeds capped only by an explicit limit, each
change said (:func:`~aerodaas.missionfile.upload.cap_speeds`), and the vehicle's read-back compared field by field
(:func:`~aerodaas.missionfile.upload.mission_differences`). End to end against the emulated vehicles:
tests/mavlink/test_mission_cli.py; on the real firmware: tests/firmware/test_sitl_fence.py."""
from __future__ import annotations

from aerodaas.missionfile import MissionItem
from aerodaas.missionfile.upload import cap_speeds, mission_differences

NAN = None


def _wp(seq, lat=47.3977420, lon=8.5455940, z=5.0, frame=3, p4=NAN):
    return MissionItem(seq=seq, command=16, frame=frame, params=[0.0, 0.0, 0.0, p4, lat, lon, z])


def _speed(seq, v):
    return MissionItem(seq=seq, command=178, frame=2, params=[1.0, v, -1.0, 0.0, 0.0, 0.0, 0.0])


def _takeoff(seq):
    return MissionItem(seq=seq, command=22, frame=3, params=[0.0, 0.0, 0.0, NAN, 47.397742, 8.545594, 5.0])


def test_the_same_mission_has_no_difference_and_a_frame_equals_its_int_twin():
    assert mission_differences([_wp(1), _speed(2, 5.0)], [_wp(1, frame=6), _speed(2, 5.0)]) == []


def test_a_position_one_grid_step_off_is_a_different_flight():
    d = mission_differences([_wp(1)], [_wp(1, lat=47.3977421)])
    assert [(x.field, x.flight) for x in d] == [("latitude", True)]
    assert str(d[0]).startswith("item 1 (MAV_CMD_NAV_WAYPOINT (16)): latitude 47.3977 sent, 47.3977 stored")


def test_an_unset_param_stored_as_zero_is_noted_not_a_different_flight():
    """ArduCopter keeps only a waypoint's hold time (AP_Mission): its yaw comes back 0."""
    d = mission_differences([_wp(1)], [_wp(1, p4=0.0)])
    assert [(x.field, x.sent, x.stored, x.flight) for x in d] == [("param4", None, 0.0, False)]


def test_a_speed_or_a_count_stored_differently_is_a_different_flight():
    d = mission_differences([_wp(1), _speed(2, 5.0), _wp(3)], [_wp(1), _speed(2, 2.0)])
    assert [(x.field, x.flight) for x in d] == [("count", True), ("param2", True)]


def test_speeds_within_the_cap_and_no_change_are_kept():
    items = [_takeoff(1), _speed(2, 1.5), _wp(3), _speed(4, -1.0)]
    out, changes = cap_speeds(items, 2.0, cruise_speed=10.0)
    assert changes == [] and [it.params for it in out] == [it.params for it in items]


def test_speeds_above_the_cap_are_capped_and_the_start_is_capped_when_the_vehicle_cruises_faster():
    items = [_takeoff(1), _wp(2), _speed(3, 5.0), _wp(4), _speed(5, -2.0)]
    out, changes = cap_speeds(items, 2.0, cruise_speed=10.0)
    assert [(it.seq, it.command, it.params[1]) for it in out] == \
        [(1, 22, 0.0), (2, 178, 2.0), (3, 16, 0.0), (4, 178, 2.0), (5, 16, 0.0), (6, 178, 2.0)]
    assert [(c.index, c.was, c.now) for c in changes] == [(2, None, 2.0), (4, 5.0, 2.0), (6, -2.0, 2.0)]
    assert str(changes[2]) == ("item 5 (MAV_CMD_DO_CHANGE_SPEED (178)): DO_CHANGE_SPEED -2 (the vehicle's default) "
                               "set to 2 m/s (--max-speed 2 m/s)")


def test_nothing_is_inserted_when_the_vehicle_cruises_slower_or_the_file_sets_the_speed_first():
    slow, _ = cap_speeds([_takeoff(1), _wp(2), _speed(3, -2.0)], 2.0, cruise_speed=1.5)
    assert [(it.command, it.params[1]) for it in slow] == [(22, 0.0), (16, 0.0), (178, -2.0)]
    first, changes = cap_speeds([_takeoff(1), _speed(2, 3.0), _wp(3)], 2.0, cruise_speed=None)
    assert [(it.command, it.params[1]) for it in first] == [(22, 0.0), (178, 2.0), (16, 0.0)]
    assert [c.was for c in changes] == [3.0]


def test_an_item_without_a_position_has_no_frame_to_compare():
    """ArduCopter returns a DO_CHANGE_SPEED sent in MAV_FRAME_MISSION (2) with frame 0 (SITL, 4.7.0-dev)."""
    stored = _speed(1, 5.0).model_copy(update={"frame": 0})
    assert mission_differences([_speed(1, 5.0)], [stored]) == []
    assert [x.field for x in mission_differences([_wp(1)], [_wp(1, frame=0)])] == ["frame"]


def _rtl(seq, frame=3):
    return MissionItem(seq=seq, command=20, frame=frame, params=[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def test_mission_planners_frame_3_on_items_without_a_position_reads_back_as_arducopter_stores_it():
    """Mission Planner writes DO_CHANGE_SPEED and RTL in frame 3; ArduCopter returns them in frame 0
    (AP_Mission::mission_cmd_to_mavlink_int: no location stored for them). That was 'a different flight': exit 2."""
    sent = [_takeoff(1), _wp(2), _speed(3, 5.0).model_copy(update={"frame": 3}), _wp(4), _rtl(5)]
    stored = [*sent[:2], _speed(3, 5.0).model_copy(update={"frame": 0}), sent[3], _rtl(5, frame=0)]
    assert mission_differences(sent, stored) == []


def test_what_arducopter_drops_of_an_item_without_a_position_is_noted_not_a_different_flight():
    sent = [_rtl(1).model_copy(update={"params": [0.0, 0.0, 0.0, 0.0, 47.3977420, 8.5455940, 30.0]})]
    d = mission_differences(sent, [_rtl(1, frame=0)])
    assert [(x.field, x.stored, x.flight) for x in d] == [("x", 0.0, False), ("y", 0.0, False), ("z", 0.0, False)]


def test_a_hold_time_or_a_speed_type_stored_differently_is_a_different_flight():
    held = _wp(1).model_copy(update={"params": [3.0, *_wp(1).params[1:]]})
    assert [(x.field, x.flight) for x in mission_differences([held], [_wp(1)])] == [("param1", True)]
    airspeed = _speed(1, 5.0).model_copy(update={"params": [0.0, 5.0, -1.0, 0.0, 0.0, 0.0, 0.0]})
    assert [(x.field, x.flight) for x in mission_differences([_speed(1, 5.0)], [airspeed])] == [("param1", True)]


def test_a_take_off_pitch_the_vehicle_does_not_keep_is_noted():
    """QGroundControl's sample .plan: NAV_TAKEOFF param1 15 (pitch, fixed-wing only); a copter stores 0."""
    pitched = _takeoff(1).model_copy(update={"params": [15.0, *_takeoff(1).params[1:]]})
    assert [(x.field, x.flight) for x in mission_differences([pitched], [_takeoff(1)])] == [("param1", False)]


def test_items_without_a_position_go_up_in_mav_frame_mission_and_each_change_is_said():
    from aerodaas.missionfile.upload import mission_frames

    items = [_takeoff(1), _speed(2, 5.0).model_copy(update={"frame": 3}), _wp(3), _speed(4, 3.0), _rtl(5)]
    out, changes = mission_frames(items)
    assert [it.frame for it in out] == [3, 2, 3, 2, 2]
    assert [it.params for it in out] == [it.params for it in items]
    assert [(c.index, c.was, c.now) for c in changes] == [(2, 3, 2), (5, 3, 2)]
    assert str(changes[1]) == ("item 5 (MAV_CMD_NAV_RETURN_TO_LAUNCH (20)): frame MAV_FRAME_GLOBAL_RELATIVE_ALT (3) "
                               "sent as MAV_FRAME_MISSION (2) (the command has no position; PX4 refuses it in a "
                               "global frame, ArduPilot stores no frame for it)")


def test_what_ardupilot_keeps_at_its_own_precision_is_noted_not_a_different_flight():
    """ArduCopter stores a hold time in whole seconds and an altitude in whole centimetres (AP_Mission): told the
    vehicle is ArduPilot, those are noted with why; any other value there, or another autopilot, is another flight."""
    from aerodaas.missionfile.upload import ardupilot_stored_altitude

    held = _wp(1, z=12.345).model_copy(update={"params": [2.5, *_wp(1).params[1:6], 12.345]})
    kept = _wp(1, z=ardupilot_stored_altitude(12.345)).model_copy(update={"params": [2.0, *_wp(1).params[1:6],
                                                                                     12.34]})
    d = mission_differences([held], [kept], autopilot="ardupilot")
    assert [(x.field, x.flight) for x in d] == [("param1", False), ("altitude", False)]
    assert d[0].explained().endswith("(ArduCopter keeps this time in whole seconds)")
    assert d[1].explained() == ("item 1 (MAV_CMD_NAV_WAYPOINT (16)): altitude 12.345 sent, 12.34 stored (ArduPilot "
                                "keeps an altitude in whole centimetres)")
    assert [(x.field, x.flight) for x in mission_differences([held], [kept], autopilot="px4")] == \
        [("param1", True), ("altitude", True)]
    other = kept.model_copy(update={"params": [0.0, *kept.params[1:6], 12.3]})  # 0 s, 12.30 m: not 2.5 nor 12.345
    assert [(x.field, x.flight) for x in mission_differences([held], [other], autopilot="ardupilot")] == \
        [("param1", True), ("altitude", True)]
    assert ardupilot_stored_altitude(-3.009) == -3.0  # truncated toward zero, as C converts a float to an int


def test_positions_read_back_as_float32_degrees_are_compared_within_float32_precision():
    """A vehicle answering with MISSION_ITEM carries degrees as float32 (about 4e-6 apart near 47 degrees), which
    its own conversion may round twice: within two float32 steps the same position, beyond it another flight."""
    assert mission_differences([_wp(1)], [_wp(1, lat=47.3977420 + 5e-6)], float_positions=True) == []
    assert [x.field for x in mission_differences([_wp(1)], [_wp(1, lat=47.3977420 + 5e-6)])] == ["latitude"]
    assert [x.field for x in mission_differences([_wp(1)], [_wp(1, lat=47.3977420 + 1e-5)], float_positions=True)] \
        == ["latitude"]
