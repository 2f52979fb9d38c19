"""A user's trajectory scheduler named in ``environment.json`` (``"trajectory_scheduler": "module:Class"``), the
class in the user's own file outside the framework's package, run by ``aerodaas run``: the drone must fly the
user's order (read from the recording with the ``mcap`` library). A misspelt name is exit 2 before Ray starts,
naming the field, the value and the closest registered scheduler."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest
from mcap.reader import make_reader

from tests.inputs.cli_inprocess import run_cli

SCHED = textwrap.dedent('''
    from aerodaas.schedulers.base import TrajectoryScheduler


    class ReverseScheduler(TrajectoryScheduler):
        """A user's order: the UNORDERED list reversed (the base class would keep it)."""

        def order(self, waypoints, start):
            return list(reversed(list(waypoints)))
''')

APP = textwrap.dedent('''
    from aerodaas import AeroNavigation, Environment, Waypoint
    from aerodaas.model.types import SchedulingType

    env = Environment("environment.json")
    drone = env.get_robot_by_id("uav")
    sched = env.trajectory_scheduler()  # the app sets none: environment.json names it
    wps = [Waypoint(id=f"w{i}", x=4.0 * i, y=0.0, z=5.0) for i in range(1, 4)]
    drone.navigate(sched.generate_navigation(
        AeroNavigation(waypoints=wps, scheduling_type=SchedulingType.UNORDERED), priority=2))
    env.start_mission([drone])
''')


def _write(tmp_path, scheduler: str) -> None:
    (tmp_path / "my_sched.py").write_text(SCHED)
    (tmp_path / "app.py").write_text(APP)
    (tmp_path / "environment.json").write_text(json.dumps({
        "name": "traj-plugin", "trajectory_scheduler": scheduler,
        "robots": [{"id": "uav", "takeoff_altitude": 5.0, "sensors": []}], "simulation": {"speedup": 20.0}}))


def _run(tmp_path, *extra: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", "app.py", "--quiet", "--timeout", "240",
                           *extra], capture_output=True, text=True, timeout=420, cwd=tmp_path, env=env)


def test_a_misspelt_trajectory_scheduler_is_exit_2_before_ray(tmp_path):
    _write(tmp_path, "NearestNeighbourScheduler")
    proc = run_cli("run", "app.py", "--quiet", "--timeout", "240", cwd=tmp_path,  # in-process: Ray refused
                   env=dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])))
    out = proc.stdout + proc.stderr
    assert proc.returncode == 2, out[-3000:]
    assert "trajectory_scheduler" in out and "'NearestNeighbourScheduler'" in out
    assert "did you mean 'NearestNeighborScheduler'?" in out
    assert "Token authentication" not in out  # Ray never started


@pytest.mark.e2e  # a whole `aerodaas run` on Ray: over the fast tier's ~20 s on a loaded machine
def test_a_users_trajectory_scheduler_named_in_environment_json_orders_the_flight(tmp_path):
    _write(tmp_path, "my_sched:ReverseScheduler")
    rec = tmp_path / "run.mcap"
    proc = _run(tmp_path, "--record", str(rec))
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    done = []
    with open(rec, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(topics=["/uav/events"]):
            ev = json.loads(message.data)
            if ev.get("event") == "waypoint_done":
                done.append(ev["waypoint"])
    assert done == ["w3", "w2", "w1"], done  # the user's ReverseScheduler decided (the default keeps w1, w2, w3)
