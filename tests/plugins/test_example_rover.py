"""The example's from-scratch ground-rover backend (examples/plugins/aerodaas_example_plugins/rover.py,
docs/extending-vehicles.md "Writing a vehicle backend from scratch"), without Ray: the unicycle's exact solution, the
controller's limits (top speed, acceleration, turn rate) and its stops, the battery, the refused commands, its
settings' errors and pre-flight checks; then a drone (the runtime's DroneComponent) driving a patrol on it, stepped by
hand on simulated time. tests/plugins/test_example_plugins.py runs the installed package's rover app with ``aerodaas run``."""
from __future__ import annotations

import importlib.util
import itertools
import math
import sys
import types

import pytest
from pydantic import ValidationError

from aerodaas.backends.base import CommandRefused, VehicleBackend
from aerodaas.config import ConfigError, RobotConfig
from aerodaas.model.types import AeroNavigation, GeoPoint, NavigationType, SchedulingType, Waypoint

from tests.conftest import REPO
from tests.recording.recorded_calls import RecordedCalls


def _load():
    """The module from its file (not installed here: its entry point is the installed package's, tested there)."""
    spec = importlib.util.spec_from_file_location(
        "example_rover", REPO / "examples" / "plugins" / "aerodaas_example_plugins" / "rover.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses resolve their annotations through it
    spec.loader.exec_module(mod)
    return mod


rover = _load()
HOME = GeoPoint(lat=47.0, lon=8.0, alt=400.0)


def _rover(**opts):
    return rover.RoverBackend(types.SimpleNamespace(id="r", home=HOME, backend_config=opts))


def test_the_rover_is_a_direct_backend_that_needs_no_take_off():
    assert rover.RoverBackend.__bases__ == (VehicleBackend,)
    assert (rover.RoverBackend.kind, rover.RoverBackend.clock, rover.RoverBackend.needs_takeoff) == (
        "ground_rover", "sim", False)
    assert not rover.RoverBackend.__abstractmethods__


def test_the_unicycle_is_solved_exactly():
    # a full circle at v = 1 m/s, omega = 0.5 rad/s (radius 2 m) ends where it began, in any number of steps
    x, y, psi = 0.0, 0.0, 0.0
    for _ in range(8):
        x, y, psi = rover.unicycle(x, y, psi, 1.0, 0.5, 2 * math.pi / 0.5 / 8)
    assert math.hypot(x, y) < 1e-9 and abs(psi) < 1e-9
    # a quarter of it: from heading east to north, 2 m east and 2 m north (the centre is at (0, 2))
    assert rover.unicycle(0.0, 0.0, 0.0, 1.0, 0.5, math.pi) == pytest.approx((2.0, 2.0, math.pi / 2))
    assert rover.unicycle(1.0, 1.0, math.pi / 2, 2.0, 0.0, 3.0) == pytest.approx((1.0, 7.0, math.pi / 2))


def _drive(r, seconds: float, dt: float = 0.1) -> list:
    samples = []
    for _ in range(round(seconds / dt)):
        r.step(dt)
        samples.append(r.telemetry.odometry())
    return samples


def test_goto_turns_on_the_spot_then_drives_within_its_limits_and_stops_on_the_target():
    r = _rover(max_speed_mps=2.0, turn_rate_dps=90.0, accel_mps2=1.0, start_yaw_deg=180.0)
    r.actions.arm()
    r.guidance.goto((10.0, 0.0, 0.0))  # due east, the rover faces west: a half turn first
    odo = _drive(r, 15.0)
    speeds = [math.hypot(*o.velocity[:2]) for o in odo]
    assert all(o.position[2] == 0.0 and not o.in_air for o in odo)
    assert max(speeds) == pytest.approx(2.0) and all(b - a <= 0.1 + 1e-9 for a, b in itertools.pairwise(speeds))
    # 9 degrees a step at 90 deg/s: on the spot while the target is behind its beam (10 steps), facing it after 20
    assert all(math.hypot(*o.position) < 1e-9 for o in odo[:10]) and math.hypot(*odo[10].position) > 1e-3
    facing = next(i for i, o in enumerate(odo) if min(o.attitude.yaw, 360.0 - o.attitude.yaw) < 1e-6)
    assert facing == 19, [round(o.attitude.yaw, 1) for o in odo[:25]]
    assert math.dist(odo[-1].position, (10.0, 0.0, 0.0)) < rover.ON_TARGET_M and speeds[-1] == 0.0
    assert max(o.position[0] for o in odo) <= 10.0 + 1e-9  # braked onto it, never past it
    # the odometry's geodetic position is the ENU one about home (about 10 m east)
    assert odo[-1].geodetic.lat == pytest.approx(47.0, abs=1e-6) and (odo[-1].geodetic.lon - 8.0) * 111_320 * \
        math.cos(math.radians(47.0)) == pytest.approx(10.0, abs=0.05)


def test_velocity_hold_and_the_battery():
    r = _rover(drain_pct_per_s=0.5, drain_pct_per_m=1.0, start_yaw_deg=0.0)
    r.actions.arm()
    r.guidance.set_velocity((0.0, -1.0, 3.0))  # south at 1 m/s; a rover ignores the vertical part
    _drive(r, 5.0)
    assert r.state().velocity == pytest.approx((0.0, -1.0, 0.0), abs=1e-9) and r.state().yaw == pytest.approx(270.0)
    driven = r.checkpoint().odometer_m
    assert r.state().battery_pct == pytest.approx(100.0 - 0.5 * 5.0 - 1.0 * driven)
    r.guidance.hold()
    _drive(r, 2.0)
    assert r.state().velocity == pytest.approx((0.0, 0.0, 0.0)) and r.state().position[2] == 0.0
    r.guidance.land()  # on the ground already: a stop, the rover stays armed until the drone disarms it
    assert r.state().armed and not r.state().in_air
    r.guidance.set_velocity((0.0, 0.0, 0.0), yaw_rate_dps=45.0)  # turn on the spot
    yaw0, pos0 = r.state().yaw, r.state().position.copy()
    _drive(r, 2.0)
    assert r.state().yaw == pytest.approx((yaw0 + 90.0) % 360) and r.state().position == pytest.approx(pos0)


def test_an_empty_battery_stops_the_rover_with_one_event_and_it_cannot_arm_again():
    r = _rover(start_battery_pct=1.0, drain_pct_per_s=0.0, drain_pct_per_m=0.5)
    r.actions.arm()
    r.guidance.goto((100.0, 0.0, 0.0))
    odo = _drive(r, 20.0)
    events = r.drain_events()
    # 1 % at 0.5 % a metre: empty after 2 m, within the step that crossed it (at most 2 m/s x 0.1 s)
    assert [e["event"] for e in events] == ["battery_empty"] and 2.0 <= events[0]["odometer_m"] <= 2.2, events
    assert r.state().battery_pct == 0.0 and odo[-1].velocity == (0.0, 0.0, 0.0)
    assert odo[-1].position[0] == pytest.approx(events[0]["odometer_m"], abs=1e-3)
    assert r.drain_events() == []
    r.actions.disarm()
    with pytest.raises(CommandRefused, match="'r': arm refused: DENIED .battery empty."):
        r.actions.arm()


def test_commands_it_cannot_carry_out_are_refused_naming_robot_and_command():
    r = _rover()
    with pytest.raises(CommandRefused, match="'r': goto refused: DENIED .not armed."):
        r.guidance.goto((1.0, 0.0, 0.0))
    with pytest.raises(CommandRefused, match="set_velocity refused"):
        r.guidance.set_velocity((1.0, 0.0, 0.0))
    r.actions.arm()
    with pytest.raises(CommandRefused, match="takeoff to 3 m refused: UNSUPPORTED"):
        r.actions.takeoff(3.0)
    r.guidance.hold()  # always accepted, armed or not
    r.actions.disarm()
    r.guidance.hold()
    with pytest.raises(ValueError, match="dt must be >= 0 s, got -0.1"):
        r.step(-0.1)


def test_a_checkpoint_restores_the_whole_state():
    r = _rover()
    r.actions.arm()
    r.guidance.goto((5.0, 5.0, 0.0))
    _drive(r, 3.0)
    saved = r.checkpoint()
    again = _rover()
    again.restore(saved)
    assert again.telemetry.odometry() == r.telemetry.odometry()
    _drive(r, 2.0), _drive(again, 2.0)
    assert again.telemetry.odometry() == r.telemetry.odometry()


@pytest.mark.parametrize("opts,field,message", [
    ({"max_speed_mps": 0}, "max_speed_mps", "greater than 0"),
    ({"turn_rate_dps": 1000}, "turn_rate_dps", "less than or equal to 720"),
    ({"accel_mps2": "fast"}, "accel_mps2", "valid number"),
    ({"top_speed": 3}, "top_speed", "Extra inputs are not permitted"),
])
def test_bad_settings_are_refused_naming_the_field(opts, field, message):
    with pytest.raises(ValidationError) as e:
        _rover(**opts)
    assert field in str(e.value) and message in str(e.value), str(e.value)


def test_its_pre_flight_checks_name_the_field_and_the_waypoint():
    robot = RobotConfig.model_validate({"id": "r", "safety": {"min_altitude": 0.5}})
    with pytest.raises(ConfigError, match=r"robots\.0\.safety\.min_altitude: 0\.5 m; a rover"):
        rover.RoverBackend.check_config(robot, "robots.0")
    rover.RoverBackend.check_config(RobotConfig.model_validate({"id": "r", "safety": {"min_altitude": 0}}), "robots.0")
    from aerodaas.schedulers.base import TrajectoryScheduler

    sched = TrajectoryScheduler()
    sched.add_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [
        Waypoint(id="a", x=3, y=0, z=0), Waypoint(id="up", x=3, y=4, z=2.5)], SchedulingType.ORDERED))
    with pytest.raises(ConfigError, match="robot 'r': waypoint 'up' at z = 2.5 m; a rover"):
        rover.RoverBackend.check_mission(types.SimpleNamespace(id="r"), sched, False)


def test_a_drone_on_the_rover_drives_its_patrol_without_a_take_off():
    """The runtime's drone (mission state machine, safety gate, waypoint holds, end of mission) on the rover,
    stepped by hand: it arms and drives (never TAKING_OFF), holds at each point, and its landing is a stop."""
    from aerodaas.actors.drone.component import DroneComponent
    from aerodaas.schedulers.base import TrajectoryScheduler

    patrol = [Waypoint(id=f"p{i}", x=x, y=y, z=0.0, hover_duration=1.0)
              for i, (x, y) in enumerate([(10.0, 0.0), (10.0, 8.0), (0.0, 8.0)], start=1)]
    cfg = RobotConfig.model_validate({"id": "r", "safety": {"min_altitude": 0.0}, "idle_land_s": 2.0})
    sched = TrajectoryScheduler()
    sched.add_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, patrol, SchedulingType.ORDERED))
    rec = RecordedCalls()
    backend = rover.RoverBackend(types.SimpleNamespace(id="r", home=cfg.home, backend_config={"start_yaw_deg": 90}))
    d = DroneComponent("r/drone", cfg.model_dump(mode="json"), None, sched, rec, 0, len(patrol), [], [],
                       backend=backend)
    d.start()
    path = []
    while backend.t < 120.0 and not d.done:
        d.step(0.1)
        d.control_tick()
        path.append(backend.telemetry.odometry())
    assert d.done and d.outcome == "success", (d.outcome, rec.events[-5:])
    assert [v["id"] for v in d.visited] == ["p1", "p2", "p3"]
    assert all(v["error_m"] <= 0.3 for v in d.visited), d.visited
    assert "TAKING_OFF" not in rec.states and rec.states[:3] == ["PREFLIGHT", "ARMED", "HOVERING"], rec.states
    assert rec.states[-2:] == ["LANDING", "LANDED"] and not backend.state().armed
    assert not any(o.in_air or o.position[2] != 0.0 for o in path)
    kinds = [e["event"] for e in rec.events]
    assert "takeoff_skipped" in kinds and "takeoff" not in kinds and not [k for k in kinds if k.endswith("_stalled")]


def test_the_backend_contract_documents_every_member_and_which_are_required():
    """docs/extending-vehicles.md "Writing a vehicle backend from scratch" names every public member of
    VehicleBackend, and its members table marks exactly the abstract ones required."""
    import re

    docs = (REPO / "docs" / "extending-vehicles.md").read_text(encoding="utf-8")
    section = docs.split("## Writing a vehicle backend from scratch", 1)[1].split("\n## ", 1)[0]
    public = {n for n in vars(VehicleBackend) if not n.startswith("_")}
    named = set(re.findall(r"`(\w+)", section))
    assert public <= named, sorted(public - named)
    members = section.split("### Members", 1)[1]
    required: dict[str, bool] = {}
    for row in members.splitlines():
        if row.startswith("| `"):
            first, req = row.split("|")[1:3]
            for name in re.findall(r"`(\w+)", first):
                required[name] = req.strip().startswith("**yes**")
    assert {n for n, r in required.items() if r} == set(VehicleBackend.__abstractmethods__), required
    assert all(not r for n, r in required.items() if n not in VehicleBackend.__abstractmethods__)


def test_a_backend_without_its_command_groups_is_refused_naming_what_is_missing(monkeypatch):
    """make_backend refuses a backend whose __init__ set no ``actions`` / ``guidance`` (or one short of a command):
    a TypeError naming the backend and the missing commands, not an AttributeError in the drone's first tick."""
    from aerodaas.backends import make_backend
    from aerodaas.plugins import registry

    rover = _load()

    class HalfRover(rover.RoverBackend):
        kind = "half_rover_test"

        def __init__(self, cfg):
            super().__init__(cfg)
            self.guidance = types.SimpleNamespace(goto=self.goto, hold=self.hold)  # no set_velocity, land, rtl

    class NoGroups(rover.RoverBackend):
        kind = "no_groups_rover_test"

        def __init__(self, cfg):
            super().__init__(cfg)
            del self.actions

    for cls in (HalfRover, NoGroups):
        monkeypatch.setattr(registry, "get", lambda kind, name, cls=cls: cls)
        cfg = types.SimpleNamespace(id="r", home=GeoPoint(lat=0.0, lon=0.0, alt=0.0), backend=cls.kind,
                                    backend_config={}, safety=None)
        with pytest.raises(TypeError) as e:
            make_backend(cfg)
        group, missing = ("guidance", "set_velocity(), land(), return_to_launch()") if cls is HalfRover else \
            ("actions", "arm(), disarm(), takeoff()")
        assert f"backend {cls.kind!r}" in str(e.value) and f"self.{group}" in str(e.value), e.value
        assert missing in str(e.value), e.value
    monkeypatch.undo()
    assert isinstance(make_backend(RobotConfig(id="d1")), VehicleBackend)  # the built-ins pass
