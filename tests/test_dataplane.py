"""The data plane (issue 6): structural facts, not wall-clock numbers.

* one host process per tier, whatever the number of drones (components are actors in placement, not processes);
* a frame is never copied between the camera and its readers (same ndarray object, read-only);
* new navigation from an analytics reaches the vehicle backend at once, not at the next control tick;
* a busy component drops (and counts) instead of queueing without bound; lock-step never drops.
"""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from aerodaas import Analytics, Environment, FollowAnalytics, PriorityQueue
from aerodaas.config import parse_environment_config
from aerodaas.models import Detection


def _env(n_drones: int = 1, fps: float = 10.0) -> Environment:
    from aerodaas.bench.fleet import fleet_config

    return Environment(parse_environment_config(fleet_config(n_drones, fps=fps, width=160, height=120)))


class FrameProbe(Analytics):
    """Remembers the frames it was given (the objects themselves) and can be made slow."""

    name = "probe"

    def __init__(self, delay_s: float = 0.0) -> None:
        super().__init__()
        self.delay_s = delay_s
        self.seen: list = []

    def process(self, frame, meta):
        self.seen.append(frame)
        if self.delay_s:
            time.sleep(self.delay_s)
        return None


class RightBox(Analytics):
    """Reports one car box three quarters of the way to the image's right edge on every frame."""

    name = "right"

    def process(self, frame, meta):
        h, w = frame.shape[:2]
        u = 0.75 * w
        return [Detection(class_id=2, class_name="car", score=0.9, box=(u - 5, h / 2 - 5, u + 5, h / 2 + 5))]


def _host_for(env: Environment, robots=None, lockstep: bool = False):
    """Plan the run as the driver does and build the edge host in this process (no Ray actors)."""
    from aerodaas.actors.components import HostRuntime
    from aerodaas.actors.host import Host
    from aerodaas.config import SimulationConfig
    from aerodaas.runtime import _collect_graph, _plan, _robot_schedulers

    robots = robots or env.get_env_robots()
    graphs = {}
    for r in robots:
        graphs[r.id] = _collect_graph(r)[0]
        for a in graphs[r.id]:
            if a.compute is None:
                a.deploy(env.get_compute_resources()[0])
    sim = SimulationConfig(lockstep=lockstep)
    plan = _plan(env, robots, graphs, _robot_schedulers(env, robots), sim, None, 0)
    host = Host("edge", "edge", 0, lockstep=lockstep, workers=2)
    rt = HostRuntime(host, plan.specs["edge"])
    host.connect(plan.routes, plan.location, {"edge": "edge"}, {})
    return host, rt, plan


def _fly(drone) -> None:
    """Put a drone component in the air, hovering (as after take-off)."""
    from aerodaas.fsm import MissionState as S

    v = drone.backend.vehicle
    v.state.position[:] = (0.0, 0.0, 3.0)
    v.state.armed = v.state.in_air = True
    for s in (S.PREFLIGHT, S.ARMED, S.TAKING_OFF, S.HOVERING):
        drone.fsm.transition(s, 0.0)


def test_frames_reach_every_reader_as_the_same_read_only_array():
    env = _env(2)
    a, b = FrameProbe(), FrameProbe()
    for r in env.get_env_robots():
        a.analyse(r.get_sensor_by_id("cam").get_data_stream())  # shared by both drones
    b.analyse(env.get_robot_by_id("d00").get_sensor_by_id("cam").get_data_stream())
    host, rt, _ = _host_for(env)
    try:
        cam = rt.drones[0].cameras[0]["comp"]
        produced = [cam.capture((0.0, 0.0, 3.0), 90.0, 0.1 * i, i) for i in range(1, 4)]
        deadline = time.time() + 5
        while (len(a.seen) < 3 or len(b.seen) < 3) and time.time() < deadline:
            time.sleep(0.01)
        pa, pb = rt.comps["probe#1"].obj, rt.comps["probe#2"].obj
        assert [id(f) for f in pa.seen] == [id(f) for f in produced] == [id(f) for f in pb.seen]  # zero copies
        assert all(not f.flags.writeable for f in produced)
        with pytest.raises(ValueError):
            produced[0][0, 0, 0] = 1  # a reader cannot change what the others see
    finally:
        rt.close()


def test_one_host_for_the_whole_fleet(ray_session, run_options):
    """Components of every drone share one worker process; the count does not grow with the fleet."""
    import ray

    from aerodaas.actors.host import HostActor

    for n in (1, 4):
        env = _env(n)
        FrameProbe().analyse(env.get_robot_by_id("d00").get_sensor_by_id("cam").get_data_stream())
        from aerodaas.runtime import _collect_graph, _plan, _robot_schedulers
        from aerodaas.config import SimulationConfig

        robots = env.get_env_robots()
        graphs = {r.id: _collect_graph(r)[0] for r in robots}
        for g in graphs.values():
            for x in g:
                x.deploy(env.get_compute_resources()[0])
        plan = _plan(env, robots, graphs, _robot_schedulers(env, robots), SimulationConfig(), None, 0)
        assert list(plan.specs) == ["edge"]  # nothing on cloud: one host
        h = HostActor.options(label_selector={"tier": "edge"}).remote("edge", "edge", 0)
        desc = ray.get(h.setup.remote(plan.specs["edge"]))
        assert len([c for c in desc["components"] if c.endswith("/drone")]) == n
        pids = {ray.get(h.pid.remote())}
        assert len(pids) == 1 and desc["pid"] in pids
        ray.get(h.close.remote())
        ray.kill(h)


def test_navigation_reaches_the_backend_before_the_next_tick():
    env = _env(1)
    drone = env.get_robot_by_id("d00")
    from aerodaas.schedulers import TrajectoryScheduler

    sched = TrajectoryScheduler(env)
    env.set_trajectory_scheduler(sched)
    follow = FollowAnalytics(target_classes=["car"], confirm_hits=1)
    det = RightBox()
    sched.add_navigation(PriorityQueue(follow.analyse(det.analyse(drone.get_sensor_by_id("cam").get_data_stream())),
                                       priority=1))
    host, rt, _ = _host_for(env)
    try:
        d = rt.drones[0]
        _fly(d)
        ticks = d.ticks
        rt.drones[0].cameras[0]["comp"].capture(tuple(d.backend.position), 90.0, 1.0, 1)
        deadline = time.time() + 5
        while d.backend.vehicle.setpoint.mode != "velocity" and time.time() < deadline:
            time.sleep(0.005)
        sp = d.backend.vehicle.setpoint
        # facing north (yaw 90), nadir camera: image right is east, so the target is east of the drone
        assert sp.mode == "velocity" and sp.velocity[0] > 0.5 and abs(sp.velocity[1]) < 0.1
        assert d.ticks == ticks and d.nudges >= 1  # applied by the nudge, no control tick ran
        rec = rt.comps["d00/scheduler"].latency[-1]
        assert rec["applied"] and rec["e2e_ms"] >= rec["overhead_ms"] >= 0
    finally:
        rt.close()


def test_busy_consumer_drops_and_counts_lockstep_never_drops():
    for lockstep in (False, True):
        env = _env(1)
        slow = FrameProbe(delay_s=0.05)
        slow.analyse(env.get_robot_by_id("d00").get_sensor_by_id("cam").get_data_stream())
        host, rt, _ = _host_for(env, lockstep=lockstep)
        try:
            from aerodaas.actors.host import Cascade

            cam = rt.drones[0].cameras[0]["comp"]
            comp = rt.comps["probe#1"]
            tok = Cascade() if lockstep else None
            threads = [threading.Thread(target=cam.capture, args=((0.0, 0.0, 3.0), 90.0, 0.01 * i, i, tok))
                       for i in range(1, 6)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            if tok is not None:
                tok.wait(10)
            time.sleep(0.3)
            assert comp.received == 5
            if lockstep:
                assert comp.dropped == 0 and len(slow.seen) + comp.stale == 5  # queued, all processed
            else:
                assert comp.dropped >= 1 and len(slow.seen) + comp.dropped + comp.stale == 5
        finally:
            rt.close()
