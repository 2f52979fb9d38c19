"""A user's analytics scheduler, written the way the README says: a subclass registered with
``register_analytics_scheduler`` in the application's own file (outside the framework's package), named in the
environment, run by ``aerodaas run``. The dispatcher actor must run the user's class: it lives only in the app,
so the runtime carries the class (pickled by value) to the actor, not its name. The run is in-process on the pytest
worker's shared Ray session (``run_cli(shared_ray=True)``): the class travels by value there as in a Ray of its own,
and the session is checked clean after."""
from __future__ import annotations

import textwrap

from aerodaas.recording.reader import read_messages

from tests.inputs.cli_inprocess import run_cli

APP = textwrap.dedent('''
    import time

    from aerodaas import AeroListData, Analytics, Environment, NearestNeighborScheduler, PriorityQueue, Waypoint
    from aerodaas.config import parse_environment_config
    from aerodaas.schedulers.analytics_base import Decision, TaskState, register_analytics_scheduler
    from aerodaas.schedulers.analytics_baselines import EdgeFifo


    @register_analytics_scheduler
    class MyEdgeFifo(EdgeFifo):
        """EDGE_FIFO that sheds every second frame with its own reason (a user's experiment)."""

        name = "MY_EDGE_FIFO"

        def __init__(self, workload):
            super().__init__(workload)
            self.seen = 0

        def submit(self, task, now_ms):
            self.seen += 1
            if self.seen % 2 == 0:
                return [Decision.drop(task, TaskState.DROPPED_COST, "my-edge-fifo: every second frame")]
            return super().submit(task, now_ms)


    class Stub(Analytics):
        name = "detector"

        def process(self, frame, meta):
            time.sleep(0.005)
            return []


    cam = {"id": "cam", "type": "camera",
           "properties": {"width": 320, "height": 240, "hfov_deg": 78, "fps": 10, "pitch_deg": 90}}
    env = Environment(parse_environment_config({
        "name": "user-scheduler", "world": {"ground": {"seed": 1, "metres_per_pixel": 0.05, "size_m": 120}},
        "robots": [{"id": "uav", "takeoff_altitude": 3.0, "sensors": [cam]}],
        "simulation": {"speedup": 4.0}}))
    env.set_analytics_scheduler("MY_EDGE_FIFO", {"detector": {"deadline_ms": 500, "edge_ms": 5, "cloud_ms": 100,
                                                              "benefit": 100, "edge_cost": 1, "cloud_cost": 20}})
    drone = env.get_robot_by_id("uav")
    sched = NearestNeighborScheduler(env)
    env.set_trajectory_scheduler(sched)
    det = Stub()
    det.deploy(env.get_compute_resource_by_id("edge"))
    det.analyse(drone.get_sensor_by_id("cam").get_data_stream())
    drone.navigate(sched.generate_navigation(PriorityQueue(AeroListData(
        [Waypoint(id="hover", x=0.0, y=0.0, z=3.0, hover_duration=4.0)]), priority=2)))
    env.start_mission([drone])
''')


def test_a_users_analytics_scheduler_in_the_app_runs_in_the_dispatcher(tmp_path, ray_session):
    app = tmp_path / "my_app.py"
    app.write_text(APP)
    rec = tmp_path / "run.mcap"
    proc = run_cli("run", str(app), "--record", str(rec), "--quiet", "--timeout", "240", cwd=tmp_path, shared_ray=True)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    tasks = [m for t, _, _, m in read_messages(str(rec)) if t == "/uav/detector/tasks"]
    assert len(tasks) >= 6, len(tasks)
    mine = [m for m in tasks if m["reason"] == "my-edge-fifo: every second frame"]
    # the user's policy decided: every second task shed with its reason, the others run on the edge
    assert len(mine) == len(tasks) // 2, [m["reason"] for m in tasks]
    assert all(m["state"] == "dropped_cost" for m in mine)
    assert any(m["state"] == "done_on_time" and m["tier"] == "edge" for m in tasks)
