"""Take-off, landing and the return to launch each have a deadline in vehicle seconds (a ground-rover
plug-in sat in TAKING_OFF for 4,000 simulated seconds until the battery failsafe ended it as failsafe_rtl). The
formula alone; the drone (:class:`~aerodaas.actors.drone.component.DroneComponent`) stepped by hand on simulated time with
backends that cannot climb, cannot land or cannot fly home, judged from its events, states and vehicle; then a
user's plug-in backends run by ``aerodaas run`` (a simulator that cannot climb, a ground vehicle that needs no
take-off), judged from the recording and the exit code."""
from __future__ import annotations

import json
import textwrap

import pytest

from aerodaas.backends.sim import SimBackend
from aerodaas.sim.vehicle import SimVehicle
from aerodaas.config import ConfigError, RobotConfig, parse_environment_config
from aerodaas.config.deadlines import PhaseDeadlinesConfig
from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.navigation import deadlines as dl

from tests.inputs.cli_inprocess import run_cli


def test_a_deadline_is_the_legs_at_the_vehicles_limits_times_the_factor_plus_the_margin():
    climb = dl.takeoff_legs(0.0, 10.0, 2.0)
    assert dl.deadline_s(climb, 2.0, 15.0) == pytest.approx(2.0 * 10.0 / 2.0 + 15.0)
    # landing is judged at the landing speed, never above the vertical limit
    assert dl.landing_legs(12.0, 3.0, 0.5)[0].speed_mps == 0.5 and dl.landing_legs(12.0, 0.2, 0.5)[0].speed_mps == 0.2
    assert dl.landing_legs(-0.3, 1.0, 0.5)[0].distance_m == 0.0
    # AeroDaaS's own return: its path only (it lands in a phase of its own)
    ours = dl.return_legs((30.0, 40.0, 5.0), [(30.0, 0.0, 5.0), (0.0, 0.0, 5.0)], 5.0, 1.0, 0.5, None)
    assert [(g.kind, g.distance_m) for g in ours] == [("horizontal", 70.0)]
    # the autopilot's RTL climbs to its return altitude, flies straight home and lands
    theirs = dl.return_legs((30.0, 40.0, 5.0), [], 5.0, 1.0, 0.5, 15.0)
    assert [(g.kind, g.distance_m, g.speed_mps) for g in theirs] == [
        ("climb", 10.0, 1.0), ("horizontal", 50.0, 5.0), ("descent", 15.0, 0.5)]
    assert dl.deadline_s(theirs, 1.0, 0.0) == pytest.approx(10.0 + 10.0 + 30.0)
    with pytest.raises(ValueError, match="speed_factor must be >= 1"):
        dl.deadline_s(climb, 0.5, 0.0)
    with pytest.raises(ValueError, match="climb leg: speed 0"):
        dl.deadline_s(dl.takeoff_legs(0.0, 1.0, 0.0), 1.0, 0.0)


@pytest.mark.parametrize("section,field,message", [
    ({"takeoff_s": -5}, "takeoff_s", "greater than 0"),
    ({"on_landing_stalled": "hold"}, "on_landing_stalled", "'land' or 'abort'"),
    ({"on_takeoff_stalled": "panic"}, "on_takeoff_stalled", "'land', 'hold' or 'abort'"),
    ({"speed_factor": 0.5}, "speed_factor", "greater than or equal to 1"),
    ({"margin_s": "10"}, "margin_s", "valid number"),
    ({"rtl": 30}, "rtl", "did you mean 'rtl_s'"),
])
def test_a_bad_deadline_setting_is_refused_naming_the_field(section, field, message):
    with pytest.raises(ConfigError) as e:
        parse_environment_config({"robots": [{"id": "d", "deadlines": section}]})
    assert f"robots.0.deadlines.{field}" in str(e.value) and message in str(e.value), str(e.value)


def test_the_defaults_are_documented_values():
    c = PhaseDeadlinesConfig()
    assert (c.speed_factor, c.margin_s, c.landing_speed, c.on_takeoff_stalled, c.on_landing_stalled,
            c.on_rtl_stalled) == (2.0, 15.0, 0.5, "land", "land", "land")


# ---------------------------------------------------------------- the drone, stepped by hand on simulated time
class NoClimbVehicle(SimVehicle):
    """Motors that lift nothing until ``lift`` is set: take-off is accepted, the vehicle stays on the ground."""

    lift = False

    def takeoff(self, altitude: float) -> None:
        super().takeoff(altitude if self.lift else 0.0)


class NoClimbSim(SimBackend):
    kind = "no_climb_sim_test"
    vehicle_class = NoClimbVehicle


class NoLandVehicle(SimVehicle):
    """Accepts LAND and keeps hovering (an autopilot whose landing never starts)."""

    def land(self) -> None:
        self.hold()


class NoLandSim(SimBackend):
    kind = "no_land_sim_test"
    vehicle_class = NoLandVehicle


class StuckVehicle(SimVehicle):
    """Holds wherever it is once ``stuck`` (a vehicle that cannot make way home: wind, a fence)."""

    stuck = False

    def goto(self, target, speed=None) -> None:
        self.hold() if self.stuck else super().goto(target, speed)


class StuckSim(SimBackend):
    kind = "stuck_sim_test"
    vehicle_class = StuckVehicle


class Recorded:
    """The recorder's calls a drone makes, kept: events in order."""

    def __init__(self) -> None:
        self.events: list[dict] = []

    def json(self, topic: str, t_ns: int, msg: dict, schema: str) -> None:
        if topic.endswith("/events"):
            self.events.append(msg)

    def odometry(self, *args, **kwargs) -> None:
        pass


def _drone(backend_cls, items=(), **robot):
    from aerodaas.actors.drone.component import DroneComponent
    from aerodaas.schedulers.base import TrajectoryScheduler

    robot = {"id": "d", "takeoff_altitude": 4.0, "limits": {"max_vertical_speed": 2.0, "max_speed": 4.0}, **robot}
    cfg = RobotConfig.model_validate(robot)
    sched = TrajectoryScheduler()
    if items:
        sched.add_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, list(items), SchedulingType.ORDERED))
    rec = Recorded()
    d = DroneComponent("d/drone", cfg.model_dump(mode="json"), None, sched, rec, 0, len(items), [], [],
                       backend=backend_cls(cfg))
    d.start()
    return d, rec


def _fly(d, until_s: float, dt: float = 0.1, on_step=None) -> list[float]:
    """Step the vehicle and the control loop by ``dt`` simulated seconds until the mission ends or ``until_s``;
    returns the vehicle's heights."""
    heights = []
    while d.backend.t < until_s and not d.done:
        d.step(dt)
        d.control_tick()
        heights.append(float(d.backend.state().position[2]))
        if on_step is not None:
            on_step(d)
    return heights


def _kinds(rec: Recorded) -> list[str]:
    return [e["event"] for e in rec.events if e["event"] not in ("action",)]


def test_a_vehicle_that_cannot_climb_is_stalled_at_its_deadline_then_landed():
    d, rec = _drone(NoClimbSim, [Waypoint(id="a", x=5, y=0, z=4)])
    heights = _fly(d, 200.0)
    stall = next(e for e in rec.events if e["event"] == "takeoff_stalled")
    # 4 m at 2 m/s, x2, + 15 s: 19 s after the take-off (the first control step saw TAKING_OFF at t = 0.1)
    assert stall["deadline_s"] == pytest.approx(19.0) and 19.0 < stall["elapsed_s"] <= 19.1 + 1e-9, stall
    assert stall["action"] == "land" and stall["legs"] == [{"kind": "climb", "distance_m": 4.0, "speed_mps": 2.0}]
    assert [s.value for _, s in d.fsm.history][-3:] == ["TAKING_OFF", "LANDING", "LANDED"]
    assert d.outcome == "takeoff_stalled" and d.done and max(heights) < 0.05 and not d.backend.state().armed
    assert d.backend.t < 25.0  # bounded: not the battery's 4,000 s


def test_a_take_off_stall_can_hold_for_the_operator_and_resume_climbs_again():
    d, rec = _drone(NoClimbSim, [Waypoint(id="a", x=5, y=0, z=4)], deadlines={"on_takeoff_stalled": "hold",
                                                                              "takeoff_s": 5.0})
    _fly(d, 8.0)
    assert d.fsm.state.value == "PAUSED" and d.outcome == "takeoff_stalled" and not d.done
    assert [e["event"] for e in rec.events][-2:] == ["takeoff_stalled", "paused"]
    assert rec.events[-2]["legs"] == [] and rec.events[-2]["deadline_s"] == 5.0  # the configured deadline
    d.backend.vehicle.lift = True  # the operator fixed the motors: resuming commands the take-off again
    d.resume_mission()
    _fly(d, 200.0)
    assert [e["event"] for e in rec.events].count("takeoff_stalled") == 1 and "waypoint_done" in _kinds(rec)
    assert d.outcome == "takeoff_stalled"  # never a success: the take-off stalled once


def test_a_take_off_stall_can_abort_the_mission():
    d, rec = _drone(NoClimbSim, deadlines={"on_takeoff_stalled": "abort", "margin_s": 3.0})
    _fly(d, 100.0)
    assert d.done and d.outcome == "takeoff_stalled" and d.fsm.state.value == "TAKING_OFF"
    assert rec.events[-1]["event"] == "takeoff_stalled" and 7.0 < d.backend.t < 7.3


def test_a_landing_that_never_starts_is_commanded_again_once_then_aborted():
    d, rec = _drone(NoLandSim, [Waypoint(id="a", x=0, y=0, z=4)], deadlines={"margin_s": 5.0})
    heights = _fly(d, 300.0)
    stalls = [e for e in rec.events if e["event"] == "landing_stalled"]
    # 4 m at 0.5 m/s, x2, + 5 s = 21 s each
    assert [s["action"] for s in stalls] == ["land", "abort"] and all(s["deadline_s"] == pytest.approx(21.0, abs=0.05)
                                                                       for s in stalls), stalls
    assert d.done and d.outcome == "landing_stalled" and min(heights[-50:]) > 3.5


def test_a_return_that_makes_no_way_home_is_stalled_and_lands_where_it_is():
    items = [Waypoint(id="a", x=20, y=0, z=4)]
    d, rec = _drone(StuckSim, items, deadlines={"margin_s": 2.0})

    def stick_after_a(drone):
        if drone.visited and not drone.backend.vehicle.stuck:
            drone.backend.vehicle.stuck = True
            drone.queue_flight.return_to_launch(drone.backend.t, tuple(drone.backend.state().position))

    _fly(d, 300.0, on_step=stick_after_a)
    stall = next(e for e in rec.events if e["event"] == "rtl_stalled")
    # 20 m home at 4 m/s, x2, + 2 s = 12 s
    assert stall["deadline_s"] == pytest.approx(12.0, abs=0.2) and stall["distance_from_home_m"] > 19.0, stall
    assert d.outcome == "rtl_stalled" and [s.value for _, s in d.fsm.history][-3:] == ["RETURNING", "LANDING",
                                                                                        "LANDED"]
    assert abs(d.backend.state().position[0] - 20.0) < 1.0 and d.backend.state().position[2] == 0.0  # landed where it was


def test_phases_within_their_deadlines_fly_as_before():
    d, rec = _drone(SimBackend, [Waypoint(id="a", x=10, y=0, z=4), Waypoint(id="b", x=0, y=0, z=4)])
    _fly(d, 300.0)
    assert d.outcome == "success" and not [e for e in rec.events if e["event"].endswith("_stalled")]


# ---------------------------------------------------------------- a user's plug-ins, run by aerodaas run
APP = textwrap.dedent('''
    from aerodaas import AeroNavigation, Environment, NavigationType, SchedulingType, Waypoint
    from aerodaas.backends.sim import SimBackend
    from aerodaas.plugins import register_backend
    from aerodaas.sim.vehicle import SimVehicle


    class WeakMotor(SimVehicle):
        def takeoff(self, altitude):
            super().takeoff(0.0)  # full throttle, no lift


    @register_backend
    class WeakMotorSim(SimBackend):
        """My test rig: the simulator with motors that cannot lift the airframe."""

        kind = "weak_motor_sim"
        vehicle_class = WeakMotor


    class GroundVehicle(SimVehicle):
        def goto(self, target, speed=None):
            super().goto((target[0], target[1], 0.0), speed)

        def land(self):
            self.hold()  # a rover is always on the ground: stop


    @register_backend
    class Rover(SimBackend):
        """A ground rover: drives to the waypoints' ground points, never flies."""

        kind = "rover"
        needs_takeoff = False
        vehicle_class = GroundVehicle


    env = Environment("env.json")
    drone = env.get_robot_by_id("r")
    drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN,
                                  [Waypoint(id="a", x=8, y=0, z=0), Waypoint(id="b", x=8, y=6, z=0)],
                                  SchedulingType.ORDERED))
    env.start_mission([drone])
''')


def _run_app(tmp_path, backend: str):
    """``aerodaas run app.py`` in this process on the worker's shared Ray session (the caller requests
    ``ray_session``; the app's backend class travels to the drone actor by value): (result, recorded messages)."""
    from aerodaas.recording.reader import read_messages

    robot = {"id": "r", "backend": backend, "takeoff_altitude": 3.0, "idle_land_s": 2.0,
             "safety": {"min_altitude": 0.0}, "limits": {"max_speed": 4.0, "max_vertical_speed": 1.0},
             "sensors": [{"id": "odom", "type": "odometry", "properties": {"rate_hz": 10}}]}
    (tmp_path / "env.json").write_text(json.dumps({"name": "deadlines", "robots": [robot],
                                                   "simulation": {"speedup": 20.0}}))
    (tmp_path / "app.py").write_text(APP)
    rec = tmp_path / "run.mcap"
    proc = run_cli("run", str(tmp_path / "app.py"), "--record", str(rec), "--quiet", "--timeout", "300",
                   cwd=tmp_path, shared_ray=True)
    return proc, [(t, m) for t, _, _, m in read_messages(str(rec))]


@pytest.mark.e2e
def test_a_users_simulator_that_cannot_climb_ends_takeoff_stalled_with_exit_1(tmp_path, ray_session):
    proc, msgs = _run_app(tmp_path, "weak_motor_sim")
    events = [m for t, m in msgs if t == "/r/events"]
    result = next(m for t, m in msgs if t == "/mission/result")
    heights = [m["position"][2] for t, m in msgs if t == "/r/odometry"]
    states = [m["state"] for t, m in msgs if t == "/mission/state"]
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "mission outcome: takeoff_stalled" in proc.stdout + proc.stderr
    stall = next(e for e in events if e["event"] == "takeoff_stalled")
    assert stall["deadline_s"] == pytest.approx(2.0 * 3.0 / 1.0 + 15.0) and stall["action"] == "land"
    assert result["outcome"] == "takeoff_stalled" and result["t"] < 60.0, result
    assert states[-3:] == ["TAKING_OFF", "LANDING", "LANDED"] and max(heights) < 0.05


@pytest.mark.e2e
def test_a_ground_vehicle_that_needs_no_take_off_drives_its_mission_without_the_deadline(tmp_path, ray_session):
    proc, msgs = _run_app(tmp_path, "rover")
    events = [m["event"] for t, m in msgs if t == "/r/events"]
    states = [m["state"] for t, m in msgs if t == "/mission/state"]
    result = next(m for t, m in msgs if t == "/mission/result")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert result["outcome"] == "success" and result["visited"] == 2, result
    assert "TAKING_OFF" not in states and states[:3] == ["PREFLIGHT", "ARMED", "HOVERING"], states
    assert "takeoff_skipped" in events and not [e for e in events if e.endswith("_stalled")], events
    odo = [m["position"] for t, m in msgs if t == "/r/odometry"]
    assert max(p[2] for p in odo) == 0.0 and max(p[1] for p in odo) > 5.5  # drove to b on the ground


@pytest.mark.e2e
def test_an_emulated_arducopter_whose_motors_lift_nothing_is_stalled_then_landed(ray_session, run_options, tmp_path):
    """The MAVLink emulator as ArduCopter SITL with every motor failed (SIM_ENGINE_FAIL 15, SIM_ENGINE_MUL 0): it
    accepts GUIDED, the arm and NAV_TAKEOFF, and never climbs. At the take-off deadline the drone records
    takeoff_stalled, switches it to LAND (the emulator's own mode log) and the run ends takeoff_stalled."""
    from aerodaas import Environment
    from aerodaas.emulators.mavlink import MavlinkVehicleEmulator
    from aerodaas.model.types import GeoPoint

    from tests.firmware.sitl import events, odometry, read_recording

    home = GeoPoint(lat=47.3977, lon=8.5456, alt=488.0)
    emu = MavlinkVehicleEmulator("ardupilot", speedup=5.0, home=home, gps_lock_s=1.0,
                                 params={"SIM_ENGINE_FAIL": 15, "SIM_ENGINE_MUL": 0})
    addr = emu.start("tcp:127.0.0.1:0")
    try:
        robot = {"id": "d", "takeoff_altitude": 2.0, "home": home.model_dump(), "backend": "mavlink",
                 "mavlink": {"connection": addr, "autopilot": "ardupilot"}, "limits": {"max_vertical_speed": 1.0},
                 "sensors": [{"id": "odom", "type": "odometry", "properties": {"rate_hz": 10}}]}
        env = Environment(parse_environment_config({"name": "no-lift", "robots": [robot],
                                                    "simulation": {"speedup": 5, "lockstep": False}}))
        d = env.get_robot_by_id("d")
        d.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=4, y=0, z=2)],
                                  SchedulingType.ORDERED))
        run_options.record = str(tmp_path / "nolift.mcap")
        res = d.start_mission(options=run_options)
        snap = emu.snapshot()
        modes = [m for _, m in emu.mode_log]
    finally:
        emu.stop()
    rec = read_recording(tmp_path / "nolift.mcap")
    ev = events(rec, "d")
    stall = next(e for e in ev if e["event"] == "takeoff_stalled")
    assert res.outcome == "takeoff_stalled" and res.robots["d"]["state"] == "LANDED", res.robots["d"]
    assert stall["deadline_s"] == pytest.approx(2.0 * 2.0 / 1.0 + 15.0) and stall["action"] == "land", stall
    assert stall["height_m"] < 0.2 and max(o["position"][2] for o in odometry(rec, "d")) < 0.2
    # the vehicle's side: GUIDED (take-off accepted), then LAND, disarmed on the ground
    assert "GUIDED" in modes and modes[-1] == "LAND" and modes.index("LAND") > modes.index("GUIDED"), modes
    assert 22 in snap["commands_seen"] and not snap["armed"] and snap["position"][2] < 0.05, snap


def test_a_return_around_an_exclusion_zone_flies_within_its_deadline():
    """The return of tests/safety/test_safety_limits.py (around a circle at (12, 0) m, several legs, each flown from rest)
    at the default deadlines: no phase is stalled, and it lands at home."""
    import pymap3d

    from aerodaas.model.types import ActionCommand

    home = {"lat": 47.3977, "lon": 8.5456, "alt": 488.0}
    lat, lon, _ = pymap3d.enu2geodetic(12.0, 0.0, 0.0, home["lat"], home["lon"], home["alt"])
    items = [Waypoint(id="a", x=0, y=8, z=3), Waypoint(id="b", x=24, y=8, z=3), Waypoint(id="c", x=24, y=0, z=3),
             Waypoint(id="d", x=24, y=-8, z=3), ActionCommand(id="home", action="rtl")]
    d, rec = _drone(SimBackend, items, home=home, takeoff_altitude=3.0, limits={"max_speed": 2.0},
                    safety={"geofence": {"circles": [{"center": [lat, lon], "radius": 4.0, "inclusion": False}]}})
    _fly(d, 600.0)
    ret = next(e for e in rec.events if e["event"] == "returning")
    assert len(ret["path"]) > 1 and not [e for e in rec.events if e["event"].endswith("_stalled")], rec.events[-5:]
    assert d.fsm.state.value == "LANDED" and abs(d.backend.state().position[0]) < 1.0 and abs(d.backend.state().position[1]) < 1.0
