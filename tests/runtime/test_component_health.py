"""Component health decides the outcome: a sensor or an analytics that fails more often than its limit
(``max_failure_fraction``) makes the run ``degraded`` (exit code 5) with the component named in the summary; every
failure is counted, the first ones recorded as events and the rest as summary events whose counts add up.

The end-to-end runs use a plug-in sensor written as a user writes one — a module outside the package, named by its
import path in ``environment.json`` — and an analytics defined in the application file, and judge them from the
summary, the exit code and the recording."""
from __future__ import annotations

import json
import re
import textwrap

import pytest

from aerodaas.recording.health import (FIRST_EVENTS, ComponentKind, FailureCount, FailureLog, assess,
                                       tally_failures)
from aerodaas.recording.reader import read_messages

from tests.inputs.cli_inprocess import CliResult, run_cli

SENSOR = textwrap.dedent('''
    from pydantic import BaseModel, Field

    from aerodaas.plugins import SensorPlugin, SensorPluginConfig


    class FlakyConfig(SensorPluginConfig):
        fail_per_20: int = Field(default=0, ge=0, le=20)


    class Reading(BaseModel):
        n: int
        z: float


    class FlakySensor(SensorPlugin):
        """Raises on ``fail_per_20`` of every 20 readings."""

        name = "flaky_altimeter"
        Config = FlakyConfig
        Message = Reading

        def setup(self):
            self.n = 0

        def sample(self, state, t):
            self.n += 1
            if self.n % 20 < self.config.fail_per_20:
                raise RuntimeError(f"altimeter bus timeout on read {self.n}")
            return Reading(n=self.n, z=float(state.position[2]))
''')

APP = textwrap.dedent('''
    from aerodaas import *

    class Broken(Analytics):
        name = "broken"

        def process(self, data, meta=None):
            if FAIL:
                raise ValueError("no model for this input")
            return None

    env = Environment(ENV)
    edge = env.get_compute_resource_by_id("edge")
    drone = env.get_robot_by_id("d1")
    scheduler = NearestNeighborScheduler(env)
    env.set_trajectory_scheduler(scheduler)
    a = Broken()
    a.deploy(edge)
    a.analyse(drone.get_sensor_by_id("odom").get_data_stream())
    wps = [Waypoint(id="wp1", x=2, y=0, z=2, hover_duration=15)]
    drone.navigate(scheduler.generate_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps,
                                                                SchedulingType.ORDERED)))
    drone.start_mission()
''')


def _env(fail_per_20: int) -> dict:
    return {"name": "health", "robots": [{
        "id": "d1", "backend": "sim", "home": {"lat": 13.0213, "lon": 77.5671, "alt": 920.0},
        "limits": {"max_speed": 2.0, "max_vertical_speed": 1.0, "max_acceleration": 2.0, "max_yaw_rate": 90},
        "takeoff_altitude": 2.0,
        "sensors": [{"id": "odom", "type": "odometry", "properties": {"rate_hz": 5}},
                    {"id": "alt", "type": "flaky_user_sensor:FlakySensor",
                     "properties": {"rate_hz": 10, "fail_per_20": fail_per_20}}]}],
        "compute": [{"id": "edge", "tier": "edge", "properties": {"cpus": 2, "memory_gb": 8, "accelerators": []}}],
        "simulation": {"speedup": 20, "physics_hz": 50}}


def _run(tmp_path, fail_per_20: int, analytics_fails: bool) -> tuple[CliResult, str]:
    """``aerodaas run app.py`` in this process on the pytest worker's shared Ray session (``run_cli``): the sensor
    module beside the app is found from the app's folder, as ``aerodaas run`` puts it first on ``sys.path``, and
    reaches the actors by value (a plug-in outside any installed package), not through their ``PYTHONPATH``."""
    (tmp_path / "flaky_user_sensor.py").write_text(SENSOR)
    (tmp_path / "env.json").write_text(json.dumps(_env(fail_per_20)))
    app = tmp_path / "app.py"
    app.write_text(APP.replace("ENV", repr(str(tmp_path / "env.json"))).replace("FAIL", repr(analytics_fails)))
    rec = tmp_path / "run.mcap"
    p = run_cli("run", str(app), "--record", str(rec), "--quiet", cwd=tmp_path, shared_ray=True)
    return p, str(rec)


def _failure_events(rec: str, kind: str) -> list[dict]:
    return [m for _, _, _, m in read_messages(rec, ["/d1/events"])
            if m.get("event") in (f"{kind}_error", f"{kind}_error_summary")]


@pytest.mark.timeout(900)
def test_a_sensor_failing_85_percent_and_an_analytics_failing_every_item_degrade_the_run(ray_session, tmp_path):
    p, rec = _run(tmp_path, fail_per_20=17, analytics_fails=True)
    out = p.stdout + p.stderr
    assert "mission outcome: degraded" in p.stdout, out[-4000:]
    assert p.returncode == 5, out[-4000:]
    m = re.search(r"DEGRADED: sensor alt of d1: (\d+) of (\d+) readings failed .*first error: "
                  r"RuntimeError: altimeter bus timeout on read 1\b", p.stdout)
    assert m, p.stdout[-3000:]
    failures, attempts = int(m.group(1)), int(m.group(2))
    readings = sum(1 for _ in read_messages(rec, ["/d1/alt"]))
    assert attempts - failures == readings and readings > 10  # every attempt is a recorded reading or a failure
    assert abs(failures / attempts - 0.85) < 0.05
    events = _failure_events(rec, "sensor")
    singles = [e for e in events if e["event"] == "sensor_error"]
    summaries = [e for e in events if e["event"] == "sensor_error_summary"]
    assert len(singles) == FIRST_EVENTS and summaries, [e["event"] for e in events]
    assert events[:FIRST_EVENTS] == singles  # the first N one by one, then summaries only
    assert sum(e["failures"] for e in events) == failures and summaries[-1]["count"] == failures
    assert all(e["last_error"].startswith("RuntimeError: altimeter bus timeout") for e in summaries)
    m = re.search(r"DEGRADED: analytics broken: (\d+) of (\d+) items failed .*first error: ValueError: no model",
                  p.stdout)
    assert m and m.group(1) == m.group(2) and int(m.group(1)) > 10, p.stdout[-3000:]
    a_events = _failure_events(rec, "analytics")
    assert sum(e["failures"] for e in a_events) == int(m.group(1))
    assert sum(1 for e in a_events if e["event"] == "analytics_error") == FIRST_EVENTS
    # the recording's tally says the same as the summary
    tally = tally_failures([rec])
    assert tally[("sensor", "d1", "alt")].failures == failures
    assert tally[("analytics", None, "broken")].failures == int(m.group(1))


@pytest.mark.timeout(900)
def test_a_sensor_failing_below_its_limit_leaves_the_run_a_success(ray_session, tmp_path):
    p, rec = _run(tmp_path, fail_per_20=2, analytics_fails=False)
    assert "mission outcome: success" in p.stdout and p.returncode == 0, (p.stdout + p.stderr)[-4000:]
    assert "DEGRADED" not in p.stdout
    m = re.search(r"sensor alt \(flaky_user_sensor:FlakySensor\): (\d+) readings .*, (\d+) failed", p.stdout)
    assert m and int(m.group(2)) > 0, p.stdout[-3000:]
    assert sum(e["failures"] for e in _failure_events(rec, "sensor")) == int(m.group(2))


def test_failure_log_records_the_first_ones_then_summaries_whose_counts_add_up():
    log = FailureLog(FailureCount(ComponentKind.SENSOR, "d1", "s"), first_events=3, every=10, period_s=1e9)
    events = []
    for i in range(57):
        log.attempt()
        if i % 2:
            continue
        ev = log.failed(i * 0.1, f"E{i}")
        if ev:
            events.append(ev)
    events.append(log.summary(6.0))
    assert [e["event"] for e in events[:3]] == ["sensor_error"] * 3
    assert all(e["event"] == "sensor_error_summary" for e in events[3:])
    assert sum(e["failures"] for e in events) == log.count.failures == 29
    assert sum(e["attempts"] for e in events) == log.count.attempts == 57
    assert events[-1]["count"] == 29 and events[-1]["last_error"] == "E56"
    assert log.summary(7.0) is None  # nothing unrecorded


def test_a_restarted_component_does_not_hide_its_recorded_failures():
    """Own counts that began at 0 again (a restarted actor) lose to the recording's tally, and the reverse."""
    recorded = {("analytics", None, "a"): FailureCount(ComponentKind.ANALYTICS, None, "a", 100, 90, "E1", "E9")}
    own = [FailureCount(ComponentKind.ANALYTICS, None, "a", 3, 0, limit=0.5)]
    (bad,) = assess(own, recorded)
    assert (bad.failures, bad.attempts, bad.first_error, bad.limit) == (90, 100, "E1", 0.5)
    assert assess([FailureCount(ComponentKind.SENSOR, "d1", "s", 100, 20)], None) == []  # at the limit: fine
    assert assess([FailureCount(ComponentKind.SENSOR, "d1", "s", 100, 21)], None)[0].label == "sensor s of d1"


def test_a_limit_outside_0_1_is_refused_naming_the_field():
    from pydantic import ValidationError

    from aerodaas.config import ConfigError
    from aerodaas.config.robot import SensorConfig
    from aerodaas.runtime.preflight import check_failure_fraction

    with pytest.raises(ValidationError, match="max_failure_fraction"):
        SensorConfig.model_validate({"id": "odom", "type": "odometry", "max_failure_fraction": 1.5})
    assert SensorConfig.model_validate({"id": "odom", "type": "odometry"}).max_failure_fraction == 0.2

    class A:
        name = "a"
        max_failure_fraction = "0.5"

    with pytest.raises(ConfigError, match=r"analytics 'a': max_failure_fraction must be a number in \[0, 1\].*'0.5'"):
        check_failure_fraction(A())
    A.max_failure_fraction = 0.5
    check_failure_fraction(A())


def test_a_log_restored_from_a_checkpoint_goes_on_counting():
    """A drone actor restarted from its checkpoint: its sensors' counts go on from there, and the events recorded
    before and after add up to the total."""
    before = FailureLog(FailureCount(ComponentKind.SENSOR, "d1", "s", limit=0.5), every=4, period_s=1e9)
    events = []
    for i in range(12):
        before.attempt()
        events.append(before.failed(float(i), f"E{i}"))
    after = FailureLog(FailureCount(ComponentKind.SENSOR, "d1", "s", limit=0.5), every=4, period_s=1e9)
    after.restore(before.state())
    for i in range(12, 20):
        after.attempt()
        events.append(after.failed(float(i), f"E{i}"))
    events.append(after.summary(20.0))
    got = [e for e in events if e]
    assert sum(1 for e in got if e["event"] == "sensor_error") == FIRST_EVENTS  # not 5 more after the restart
    assert sum(e["failures"] for e in got) == after.count.failures == 20 and after.count.limit == 0.5
    assert after.count.first_error == "E0"
