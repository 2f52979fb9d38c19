"""`aerodaas run` of a fleet application that starts its mission with ``env.start_mission([d1, d2])`` (such
a run flew, then printed "the application never called start_mission()" and exited 1): the CLI entry flies both
drones, prints the summary and exits 0 (in-process on the pytest worker's shared Ray session); and the fleet start's
own argument checks."""
from __future__ import annotations

import pytest

from aerodaas import Environment
from aerodaas.recording.metrics import waypoint_visits
from aerodaas.recording.reader import read_messages

from tests.conftest import REPO
from tests.inputs.cli_inprocess import run_cli

APP = REPO / "tests" / "apps" / "fleet_two_drones.py"


@pytest.mark.e2e
def test_aerodaas_run_of_a_fleet_app_prints_the_summary_and_exits_0(tmp_path, ray_session):
    rec = tmp_path / "fleet.mcap"
    proc = run_cli("run", str(APP), "--speedup", "20", "--quiet", "--record", str(rec), cwd=tmp_path, shared_ray=True)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "never called start_mission" not in out
    assert "mission outcome: success" in proc.stdout
    assert "robot d1:" in proc.stdout and "robot d2:" in proc.stdout
    assert proc.stdout.count("mission outcome:") == 1  # one summary for the one fleet mission
    odom: dict[str, list] = {"d1": [], "d2": []}
    for topic, _schema, _t, msg in read_messages(str(rec)):
        if isinstance(msg, dict) and topic.endswith("/odometry"):
            odom[msg["robot_id"]].append(msg)
    for rid, wp in (("d1", (4.0, 0.0, 2.0)), ("d2", (4.0, 3.0, 2.0))):  # each flew to its own waypoint, and landed
        (visit,) = waypoint_visits(odom[rid], [wp], 0.5)
        assert visit["closest_m"] <= 0.5, (rid, visit)
        assert odom[rid][-1]["position"][2] == pytest.approx(0.0, abs=0.1)


def test_fleet_start_refuses_a_foreign_or_repeated_robot_before_anything_starts():
    env = Environment(REPO / "tests" / "apps" / "fleet_two_drones.json")
    other = Environment(REPO / "tests" / "apps" / "fleet_two_drones.json")
    d1 = env.get_robot_by_id("d1")
    with pytest.raises(ValueError, match=r"robots\[1\] \('d1'\) is given twice"):
        env.start_mission([d1, "d1"])
    with pytest.raises(ValueError, match=r"robots\[0\] must be a Robot of this environment"):
        env.start_mission([other.get_robot_by_id("d2")])
    with pytest.raises(ValueError, match=r"robots\[0\] must be a Robot .* got 3"):
        env.start_mission([3])
    with pytest.raises(KeyError, match="unknown robot id 'd9'"):
        env.start_mission(["d9"])
