"""The data plane (issue 6): structural facts, not wall-clock numbers.

* one host process per tier, whatever the number of drones (components are actors in placement, not processes),
  counted on the Ray node during a real run;
* a frame is never copied between the camera and its readers (same ndarray object, read-only); the recorder
  JPEG-encodes each recorded frame once; a frame crossing to the cloud tier is encoded once and decoded once;
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


def _env(n_drones: int = 1, fps: float = 10.0, lockstep: bool = False) -> Environment:
    """The fleet benchmark's environment at 160x120, with an edge and a cloud compute resource."""
    from aerodaas.bench.fleet import fleet_config

    cfg = fleet_config(n_drones, fps=fps, width=160, height=120)
    cfg["compute"] = [{"id": "edge", "tier": "edge"}, {"id": "cloud", "tier": "cloud"}]
    cfg["simulation"]["lockstep"] = lockstep
    return Environment(parse_environment_config(cfg))


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
    """Reports one car box three quarters of the way to the image's right edge on every frame; remembers the frames."""

    name = "right"

    def __init__(self) -> None:
        super().__init__()
        self.seen: list = []

    def process(self, frame, meta):
        self.seen.append(frame)
        h, w = frame.shape[:2]
        u = 0.75 * w
        return [Detection(class_id=2, class_name="car", score=0.9, box=(u - 5, h / 2 - 5, u + 5, h / 2 + 5))]


def _host_for(env: Environment, robots=None, lockstep: bool = False, record: str | None = None):
    """Plan the run as the driver does and build the edge host in this process (no Ray actors); ``record``: an
    MCAP path for the host's recorder."""
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
                a.deploy(env.get_compute_resource_by_id("edge"))
    sim = SimulationConfig(lockstep=lockstep)
    plan = _plan(env, robots, graphs, _robot_schedulers(env, robots), sim, record, 0)
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


def _ray_processes_titled(keep) -> list:
    """psutil processes of this driver's Ray node whose title (Ray titles a worker ``ray::<Class>`` or
    ``ray::<Class>.<method>``, an idle one ``ray::IDLE``) satisfies ``keep(title)``."""
    import psutil

    from aerodaas.bench.procs import ray_processes

    out = []
    for p in ray_processes():
        try:
            title = " ".join(p.cmdline())
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        if keep(title):
            out.append(p)
    return out


def _host_processes() -> list:
    """Processes running a HostActor."""
    return _ray_processes_titled(lambda t: t.startswith("ray::HostActor"))


def _worker_processes() -> list:
    """Processes running an actor or task, other than Ray's own agents and idle pooled workers."""
    return _ray_processes_titled(lambda t: t.startswith("ray::") and not t.startswith(
        ("ray::IDLE", "ray::DashboardAgent", "ray::RuntimeEnvAgent")))


def test_one_host_process_per_tier_whatever_the_fleet(ray_session, run_options):
    """A real run (Environment.start_mission on the session's Ray): the worker processes it creates are one
    HostActor per tier in use, for 1 drone as for 4 (counted on the node while the hosts are up)."""
    import psutil
    import ray

    for p in _host_processes():  # hosts of earlier tests, killed, may take a moment to exit
        try:
            p.wait(30)
        except psutil.NoSuchProcess:
            pass
    before = {p.pid for p in _worker_processes()}  # actors earlier tests of the session left running are not ours
    seen: dict[int, dict] = {}
    for n in (1, 4):
        env = _env(n)
        probe = FrameProbe()
        probe.deploy(env.get_compute_resource_by_id("edge"))
        for r in env.get_env_robots():
            probe.analyse(r.get_sensor_by_id("cam").get_data_stream())  # one analytics shared by the fleet

        def count(robot, n=n):
            host_pid = ray.get(robot._handle.host.pid.remote())
            seen[n] = {"hosts": sorted(p.pid for p in _host_processes()),
                       "workers": sorted(p.pid for p in _worker_processes() if p.pid not in before),
                       "edge_pid": host_pid}

        env.get_robot_by_id("d00").on_mission_start(count)
        res = env.start_mission(timeout=1.5)
        assert set(res.robots) == {f"d{i:02d}" for i in range(n)}
        assert res.stats["_hosts"].keys() == {"edge"}  # nothing deployed on cloud: one host
        try:  # the killed host's process is gone before the next fleet starts
            psutil.Process(seen[n]["edge_pid"]).wait(30)
        except psutil.NoSuchProcess:
            pass
    for n in (1, 4):
        assert seen[n]["hosts"] == [seen[n]["edge_pid"]], seen  # one HostActor process: the edge host
        assert seen[n]["workers"] == seen[n]["hosts"], seen  # and no other worker process of the run
    assert len(seen[4]["workers"]) == len(seen[1]["workers"]) == 1


def test_frame_copies_on_the_edge_hot_path_and_the_recorder(tmp_path):
    """camera -> detector -> follow -> scheduler -> drone, another frame reader, and the recorder, on one host:
    the pixels are materialised once by the camera, reach both readers as the same object (0 copies), and are
    JPEG-encoded exactly once per recorded frame; nothing is encoded or put in the object store."""
    env = _env(1)
    drone = env.get_robot_by_id("d00")
    from aerodaas.schedulers import TrajectoryScheduler

    sched = TrajectoryScheduler(env)
    env.set_trajectory_scheduler(sched)
    cam_stream = drone.get_sensor_by_id("cam").get_data_stream()
    det, other = RightBox(), FrameProbe()
    follow = FollowAnalytics(target_classes=["car"], confirm_hits=1)
    sched.add_navigation(PriorityQueue(follow.analyse(det.analyse(cam_stream)), priority=1))
    other.analyse(cam_stream)
    host, rt, _ = _host_for(env, record=str(tmp_path / "copies.mcap"))
    try:
        d = rt.drones[0]
        _fly(d)
        cam = d.cameras[0]["comp"]
        produced = []
        for i in range(1, 4):
            produced.append(cam.capture(tuple(d.backend.position), 90.0, 0.1 * i, i))
            deadline = time.time() + 5  # one frame at a time: no reader is busy, nothing is dropped
            while (len(det.seen) < i or len(other.seen) < i
                   or len(rt.comps["d00/scheduler"].latency) < i) and time.time() < deadline:
                time.sleep(0.005)
        assert [id(f) for f in det.seen] == [id(f) for f in produced] == [id(f) for f in other.seen]  # 0 copies
        assert len(rt.comps["d00/scheduler"].latency) == 3  # every frame's navigation reached the drone
    finally:
        counts = rt.close()  # the recorder encodes what it has queued, then finishes the file
    copies = host.copies.snapshot()
    assert rt.stats()["_host"]["frame_copies"] == copies
    assert counts["/d00/camera/cam"] == 3
    assert copies == {"materialised": 3, "recorder_jpeg_encoded": 3, "tier_jpeg_encoded": 0, "tier_jpeg_decoded": 0,
                      "object_store_put": 0, "object_store_get": 0}


def test_frame_crossing_to_the_cloud_is_encoded_once_and_decoded_once(ray_session, run_options):
    """A real lock-step run with a frame analytics deployed on the cloud tier: every frame the edge camera
    materialises is JPEG-encoded once on the edge host and decoded once on the cloud host (and nothing else)."""
    env = _env(1, lockstep=True)
    probe = FrameProbe()
    probe.deploy(env.get_compute_resource_by_id("cloud"))
    probe.analyse(env.get_robot_by_id("d00").get_sensor_by_id("cam").get_data_stream())
    res = env.start_mission(timeout=3.0)
    hosts = res.stats["_hosts"]
    assert set(hosts) == {"edge", "cloud"} and hosts["edge"]["error_count"] == hosts["cloud"]["error_count"] == 0
    edge, cloud = hosts["edge"]["frame_copies"], hosts["cloud"]["frame_copies"]
    cam = res.stats["d00"]["cameras"]["cam"]
    analysed = res.stats["d00"]["analytics"][0]
    n = cam["frames"]
    assert n > 0 and analysed["processed"] == analysed["received"] == n  # lock-step: every frame crossed
    assert [o["sent"] for o in cam["outlets"]] == [n] and cam["outlets"][0]["dropped"] == 0
    assert edge == {"materialised": n, "tier_jpeg_encoded": n, "tier_jpeg_decoded": 0, "object_store_put": 0,
                    "object_store_get": 0, "recorder_jpeg_encoded": 0}
    assert cloud == {"materialised": 0, "tier_jpeg_encoded": 0, "tier_jpeg_decoded": n, "object_store_put": 0,
                     "object_store_get": 0, "recorder_jpeg_encoded": 0}
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
