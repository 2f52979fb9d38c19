"""The data plane: structural facts, not wall-clock numbers.

* one drone actor per drone (or per ``drones_per_actor`` drones), one actor per deployed analytics and one recorder
  per run, counted on the Ray node during a real run and found by their names;
* a frame is never copied between the camera and its readers in the drone actor (same ndarray object, read-only);
  the recorder's JPEG encode happens once per recorded frame; a frame crossing to an analytics actor of the same
  tier is put into the object store once and read once; one crossing to the cloud tier is encoded once and
  decoded once;
* new navigation from an analytics reaches the vehicle backend at once, not at the next control tick;
* a busy component drops (and counts) instead of queueing without bound; lock-step never drops.
"""
from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest

from aerodaas import Analytics, Environment, FollowAnalytics, PriorityQueue
from aerodaas.config import parse_environment_config
from aerodaas.model.types import Detection


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


class Spotter(RightBox):
    """RightBox that keeps no frame (an analytics in its own actor: a kept frame would keep its channel slot)."""

    name = "spotter"

    def process(self, frame, meta):
        out = super().process(frame, meta)
        self.seen.clear()
        return out


def _host_for(env: Environment, robots=None, lockstep: bool = False, record: str | None = None):
    """Plan the run as the driver does, with every analytics colocated and every drone in one drone actor, and
    build that actor's host in this process (no Ray actors); ``record``: an MCAP path for an in-process recorder."""
    from aerodaas.actors.host.assembly import ActorAssembly
    from aerodaas.actors.data.plane import DataPlane
    from aerodaas.config import SimulationConfig
    from aerodaas.runtime.dataflow import build_plan, collect_graph
    from aerodaas.runtime.preflight import robot_schedulers as _robot_schedulers
    from aerodaas.protocol.specs import RecordSpec

    robots = robots or env.get_env_robots()
    env.cfg.drones_per_actor = len(robots)
    graphs = {}
    for r in robots:
        graphs[r.id] = collect_graph(r)
        for a in graphs[r.id]:
            a.deploy(env.get_compute_resource_by_id("edge"), colocate=True)
    sim = SimulationConfig(lockstep=lockstep)
    plan = build_plan(env, robots, graphs, _robot_schedulers(env, robots), sim)
    (hid,) = [h for h, a in plan.actors.items() if a.role == "drone"]
    spec = dataclasses.replace(plan.actors[hid].spec, record_remote=None,
                               record=RecordSpec(record) if record else None)
    host = DataPlane(hid, "edge", 0, workers=2)
    rt = ActorAssembly(host, spec)
    host.connect(plan.routes(), plan.location(), {h: a.tier for h, a in plan.actors.items()}, {})
    return host, rt, plan


def _fly(drone) -> None:
    """Put a drone component in the air, hovering (as after take-off)."""
    from aerodaas.navigation.fsm import MissionState as S

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
        pa, pb = rt.comps["probe#1@d00"].obj, rt.comps["probe#2@d00"].obj
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


def _worker_processes() -> list:
    """Processes running an actor or task, other than Ray's own agents and idle pooled workers."""
    return _ray_processes_titled(lambda t: t.startswith("ray::") and not t.startswith(
        ("ray::IDLE", "ray::DashboardAgent", "ray::RuntimeEnvAgent")))


def _titles(pids: list[int]) -> list[str]:
    import psutil

    out = []
    for pid in pids:
        try:
            out.append(" ".join(psutil.Process(pid).cmdline()).split(".")[0].split()[0])
        except psutil.NoSuchProcess:
            out.append("gone")
    return sorted(out)


@pytest.mark.parametrize("n,per_actor", [(1, 1), (4, 1), (4, 2)])
def test_a_drone_actor_per_drone_an_actor_per_analytics_and_a_recorder(ray_session, run_options, n, per_actor):
    """A real run (Environment.start_mission on the session's Ray): the worker processes it creates are one
    DroneActor per drone (per ``drones_per_actor`` drones), one AnalyticsActor for the analytics the fleet shares
    and one RecorderActor, each found under its name ``aerodaas/<run>/...`` while the run is up."""
    import psutil
    import ray

    before = {p.pid for p in _worker_processes()}  # actors earlier tests of the session left running are not ours
    env = _env(n)
    env.cfg.drones_per_actor = per_actor
    probe = FrameProbe()
    probe.deploy(env.get_compute_resource_by_id("edge"))
    for r in env.get_env_robots():
        probe.analyse(r.get_sensor_by_id("cam").get_data_stream())  # one analytics shared by the fleet
    run_options.run_id = f"dp{n}x{per_actor}"
    seen: dict = {}

    def count(robot):
        groups = [f"drone/d{i:02d}" for i in range(n)] if per_actor == 1 else \
            [f"drones/d{i:02d}+{per_actor - 1}" for i in range(0, n, per_actor)]
        names = [f"aerodaas/{run_options.run_id}/{g}" for g in groups] + [
            f"aerodaas/{run_options.run_id}/analytics/edge/probe#1", f"aerodaas/{run_options.run_id}/recorder"]
        seen["pids"] = {nm: ray.get(ray.get_actor(nm).ping.remote()) for nm in names}
        seen["workers"] = sorted(p.pid for p in _worker_processes() if p.pid not in before)

    env.get_robot_by_id("d00").on_mission_start(count)
    res = env.start_mission(timeout=2.0, options=run_options)
    assert set(res.robots) == {f"d{i:02d}" for i in range(n)}
    n_actors = -(-n // per_actor)
    assert sorted(seen["pids"].values()) == seen["workers"], seen  # every worker process of the run is named
    assert _titles(seen["workers"]) == sorted(["ray::DroneActor"] * n_actors + ["ray::AnalyticsActor",
                                                                                  "ray::RecorderActor"]) or \
        len(seen["workers"]) == n_actors + 2, seen
    assert len(set(seen["pids"].values())) == n_actors + 2
    assert set(res.stats["_hosts"]) == {*(h.split("aerodaas/" + run_options.run_id + "/")[1]
                                          for h in seen["pids"])}
    for pid in seen["workers"]:  # killed at the end of the run
        try:
            psutil.Process(pid).wait(30)
        except psutil.NoSuchProcess:
            pass


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
            produced.append(cam.capture(tuple(d.backend.state().position), 90.0, 0.1 * i, i))
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
                      "object_store_put": 0, "object_store_get": 0, "channel_copy": 0,
                      "channel_in_place": 0}


@pytest.mark.parametrize("where", ["edge", "cloud"])
def test_frame_crossing_to_an_analytics_actor_is_put_once_or_encoded_once(ray_session, run_options, where):
    """A real lock-step run with a frame analytics in its own actor: on the same tier every frame the drone actor
    materialises is copied once into a same-node channel slot or made in one (lock-step uses the same transport as a
    free-running run) and read in place by the analytics actor; across tiers (cloud) it is JPEG-encoded once by the
    drone actor and decoded once by the analytics actor — nothing else. (The probe keeps every frame, so after the
    outlet's few slots were lent the frames cannot be made in one: both counters are used.) The lock-step clock
    waits for the analytics, so it is never late and sheds no frame."""
    env = _env(1, lockstep=True)
    probe = FrameProbe()
    probe.deploy(env.get_compute_resource_by_id(where))
    probe.analyse(env.get_robot_by_id("d00").get_sensor_by_id("cam").get_data_stream())
    res = env.start_mission(timeout=3.0, options=run_options)
    hosts = res.stats["_hosts"]
    a_host = f"analytics/{where}/probe#1"
    assert set(hosts) == {"recorder", "drone/d00", a_host}
    assert hosts["drone/d00"]["error_count"] == hosts[a_host]["error_count"] == 0
    drone, ana = hosts["drone/d00"]["frame_copies"], hosts[a_host]["frame_copies"]
    cam = res.stats["d00"]["cameras"]["cam"]
    analysed = res.stats["d00"]["analytics"][0]
    n = cam["frames"]
    assert n > 0 and analysed["processed"] == analysed["received"] == n  # lock-step: every frame crossed
    assert res.robots["d00"]["frames_shed_late"] == 0, res.robots["d00"]
    assert [o["sent"] for o in cam["outlets"]] == [n] and cam["outlets"][0]["dropped"] == 0
    cross = where != "edge"
    assert cam["outlets"][0]["transport"] == ("ray" if cross else "channel")
    crossed = drone.pop("channel_copy") + drone.pop("channel_in_place")
    assert crossed == (0 if cross else n)
    assert drone == {"materialised": n, "tier_jpeg_encoded": n if cross else 0, "tier_jpeg_decoded": 0,
                     "object_store_put": 0, "object_store_get": 0, "recorder_jpeg_encoded": 0}
    assert ana == {"materialised": 0, "tier_jpeg_encoded": 0, "tier_jpeg_decoded": n if cross else 0,
                   "object_store_put": 0, "object_store_get": 0, "recorder_jpeg_encoded": 0,
                   "channel_copy": 0, "channel_in_place": 0}


@pytest.mark.parametrize("transport", ["channel", "ray"])
def test_same_node_frames_travel_by_channel_or_by_ray(ray_session, run_options, transport):
    """A real run (not lock-step) with a frame analytics in its own actor on this node and navigation coming back:
    with ``same_node_transport: channel`` every frame that left the drone actor was copied once into a shared-memory
    slot or rendered straight into one (the simulator's camera renders into a slot the channel lends) and nothing
    went through the object store; with ``ray`` each was put once and read once. Either way the
    analytics saw every frame that was sent, and its results reached the drone's trajectory scheduler."""
    env = _env(1)
    env.cfg.same_node_transport = transport
    drone = env.get_robot_by_id("d00")
    from aerodaas.schedulers import TrajectoryScheduler

    sched = TrajectoryScheduler(env)
    env.set_trajectory_scheduler(sched)
    det = Spotter()
    det.deploy(env.get_compute_resource_by_id("edge"))  # its own actor
    follow = FollowAnalytics(target_classes=["car"], confirm_hits=1)
    follow.deploy(env.get_compute_resource_by_id("edge"), colocate=True)  # in the drone actor: results come back
    sched.add_navigation(PriorityQueue(follow.analyse(det.analyse(drone.get_sensor_by_id("cam").get_data_stream())),
                                       priority=1))
    res = env.start_mission(timeout=4.0, options=run_options)
    hosts = res.stats["_hosts"]
    d_copies, a_copies = hosts["drone/d00"]["frame_copies"], hosts["analytics/edge/spotter#1"]["frame_copies"]
    cam = res.stats["d00"]["cameras"]["cam"]
    (outlet,) = cam["outlets"]
    sent = outlet["sent"]
    analysed = next(a for a in res.stats["d00"]["analytics"] if a["name"] == "spotter")
    assert sent > 10 and outlet["transport"] == transport and outlet["failed"] == 0
    assert res.stats["_settle"]["idle"]  # nothing was left in flight when the counts were taken
    assert analysed["received"] == sent and analysed["errors"] == 0
    if transport == "channel":
        assert d_copies["channel_copy"] + d_copies["channel_in_place"] == sent and d_copies["object_store_put"] == 0
        assert d_copies["channel_in_place"] == outlet["in_place"] > 0  # rendered in the slot it was sent from
        assert a_copies["object_store_get"] == 0
    else:
        assert d_copies["object_store_put"] == sent == a_copies["object_store_get"]
        assert d_copies["channel_copy"] == d_copies["channel_in_place"] == 0
    lat = res.stats["d00"]["scheduler"]
    assert lat["frames_with_latency"] > 0  # navigation from the other actor's detections reached this drone
    assert all(k in r for r in lat["latency_records"] for k in ("put_ms", "call_ms", "get_ms"))


def test_lockstep_frames_travel_by_channel_and_every_frame_is_processed(ray_session, run_options):
    """Lock-step is a property of the clock, not of the transport: a lock-step run with the detector in its own
    actor on this node moves every frame over the same-node channel (copied once into a slot or rendered in one,
    nothing through the object store), drops none, and the detector processes exactly the frames that were sent; each frame's
    detections come back in the channel's answer within the frame's cascade, so the follow analytics in the drone
    actor sees every one of them (from the runtime's counters, not from timing)."""
    env = _env(1, lockstep=True)
    drone = env.get_robot_by_id("d00")
    from aerodaas.schedulers import TrajectoryScheduler

    sched = TrajectoryScheduler(env)
    env.set_trajectory_scheduler(sched)
    det = Spotter()
    det.deploy(env.get_compute_resource_by_id("edge"))  # its own actor
    follow = FollowAnalytics(target_classes=["car"], confirm_hits=1)
    follow.deploy(env.get_compute_resource_by_id("edge"), colocate=True)
    sched.add_navigation(PriorityQueue(follow.analyse(det.analyse(drone.get_sensor_by_id("cam").get_data_stream())),
                                       priority=1))
    res = env.start_mission(timeout=4.0, options=run_options)
    hosts = res.stats["_hosts"]
    assert all(h["error_count"] == 0 for h in hosts.values())
    d_copies, a_copies = hosts["drone/d00"]["frame_copies"], hosts["analytics/edge/spotter#1"]["frame_copies"]
    cam = res.stats["d00"]["cameras"]["cam"]
    (outlet,) = cam["outlets"]
    sent = outlet["sent"]
    by_name = {a["name"]: a for a in res.stats["d00"]["analytics"]}
    spotter, follow_stats = by_name["spotter"], by_name["follow"]
    assert outlet["transport"] == "channel" and outlet["dropped"] == outlet["failed"] == 0
    assert sent == cam["frames"] > 10
    assert spotter["received"] == spotter["processed"] == sent and spotter["dropped"] == spotter["errors"] == 0
    assert d_copies["channel_copy"] + d_copies["channel_in_place"] == sent
    assert d_copies["object_store_put"] == a_copies["object_store_get"] == 0
    assert follow_stats["received"] == sent and follow_stats["dropped"] == 0  # every reply, within its cascade
    assert res.stats["d00"]["scheduler"]["frames_with_latency"] > 0


def test_components_are_called_by_their_methods_never_by_name():
    """An actor runs a component's public method given as the function itself (what the driver's typed handles
    send); a method name, another component class's method or a private method is refused with a TypeError, and
    a handle has no attribute for a method it does not declare (a typo fails in the driver)."""
    from aerodaas.actors.host.base import ActorBase
    from aerodaas.actors.drone.component import DroneComponent
    from aerodaas.actors.drone.scheduler_component import SchedulerComponent
    from aerodaas.actors.builtin.handles import DroneHandle

    env = _env(1)
    host, rt, _ = _host_for(env)
    try:
        actor = object.__new__(ActorBase)  # the Ray actor's plain body, without Ray
        actor.plane, actor.runtime = host, rt
        assert actor.call("d00/drone", DroneComponent.status)["robot"] == "d00"
        assert actor.call("d00/scheduler", SchedulerComponent.snapshot) == rt.comps["d00/scheduler"].snapshot()
        for bad in ("status", SchedulerComponent.snapshot, DroneComponent._event):
            with pytest.raises(TypeError, match="not one of its public methods"):
                actor.call("d00/drone", bad)
        with pytest.raises(AttributeError):
            DroneHandle(None, "d00/drone").statuss  # noqa: B018 - the typo itself is the test
    finally:
        rt.close()


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
        rt.drones[0].cameras[0]["comp"].capture(tuple(d.backend.state().position), 90.0, 1.0, 1)
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
            from aerodaas.actors.data.plane import Cascade

            cam = rt.drones[0].cameras[0]["comp"]
            comp = rt.comps["probe#1@d00"]
            tok = Cascade() if lockstep else None
            threads = [threading.Thread(target=cam.capture, args=((0.0, 0.0, 3.0), 90.0, 0.01 * i, i, tok))
                       for i in range(1, 6)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            if tok is not None:
                tok.wait(10)
            deadline = time.monotonic() + 30  # every frame delivered and, queued ones, processed: a generous wait
            while (comp.received < 5 or len(slow.seen) + comp.dropped + comp.stale < 5) and time.monotonic() < deadline:
                time.sleep(0.01)
            assert comp.received == 5
            if lockstep:
                assert comp.dropped == 0 and len(slow.seen) + comp.stale == 5  # queued, all processed
            else:
                assert comp.dropped >= 1 and len(slow.seen) + comp.dropped + comp.stale == 5
        finally:
            rt.close()


class BatchProbe(Analytics):
    """Takes up to 4 frames per call (``max_batch``) and remembers each call's size. A single frame's call says it
    has started (``entered``) and holds on until the test sets ``release``, so frames offered meanwhile queue."""

    name = "batchprobe"
    max_batch = 4

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[int] = []
        self.entered, self.release = threading.Event(), threading.Event()

    def process(self, frame, meta):
        self.calls.append(1)
        self.entered.set()
        assert self.release.wait(60), "the test never released the first frame"
        return {"n": 1}

    def process_batch(self, items):
        self.calls.append(len(items))
        return [{"n": len(items)} for _ in items]


def test_frames_waiting_for_one_analytics_go_in_one_batch_call():
    """Frames of three drones arriving while the detector is busy wait in its mailbox and reach it in one
    process_batch call (its max_batch allows 4); every frame still gets its own output, in order."""
    from aerodaas.actors.analytics.component import AnalyticsComponent
    from aerodaas.actors.data.plane import DataPlane
    from aerodaas.protocol.messages import FrameMsg, Port
    from aerodaas.model.types import CameraIntrinsics, FrameMeta, FramePose

    host = DataPlane("analytics/edge/batchprobe#1", "edge", 0, workers=2)
    obj = BatchProbe()
    comp = host.add(AnalyticsComponent(host, "batchprobe#1", "batchprobe", obj, None, 0, buffer=4))
    published: list = []
    host.publish = lambda src, envs, tok=None, inline=True: published.extend(envs)  # what it hands on
    k = CameraIntrinsics.from_hfov(16, 12, 78.0)

    def env(robot: str, t: float) -> FrameMsg:
        meta = FrameMeta(robot_id=robot, sensor_id="cam", seq=1, capture_time=t, wall_time=time.time(), intrinsics=k,
                         pose=FramePose(position=(0.0, 0.0, 3.0), yaw=90.0))
        return FrameMsg(robot=robot, sim_t=t, data=np.zeros((12, 16, 3), np.uint8), meta=meta)

    first = threading.Thread(target=comp.offer, args=(Port("in"), env("d00", 0.1)))
    first.start()
    assert obj.entered.wait(60)  # d00's frame is being processed (and held there): the next three wait
    for r in ("d01", "d02", "d03"):
        assert comp.offer(Port("in"), env(r, 0.1))
    obj.release.set()
    first.join(60)  # the thread that took d00 drains the mailbox and publishes before it returns
    assert not first.is_alive()
    host.close()
    assert obj.calls == [1, 3], obj.calls  # one alone, then the three that waited in one call
    assert [m.robot for m in published] == ["d00", "d01", "d02", "d03"] and comp.batched == 3
    assert comp.processed == 4 and comp.dropped == 0


def test_settle_waits_for_work_in_flight_and_says_when_it_ran_out_of_time():
    """What the end of a run relies on to count a frame at both ends (see ``aerodaas.runtime.supervise.
    settle_actors``): ``DataPlane.settle`` returns only once no pool job, mailbox or outlet holds a message; with
    a consumer stuck it returns after its bound saying so; once idle, a second call had nothing to wait for."""
    from aerodaas.actors.data.plane import Component, DataPlane
    from aerodaas.protocol.messages import Message, Port

    release, entered = threading.Event(), threading.Event()

    class Stuck(Component):
        def handle(self, port, msg):
            entered.set()
            release.wait(30)
            return None

    host = DataPlane("analytics/edge/stuck#1", "edge", 0, workers=2)
    comp = host.add(Stuck(host, "stuck#1", buffer=2))
    try:
        assert host.settle(0.0).idle and not host.settle(0.0).waited  # nothing yet
        host.later(None, comp.offer, Port("in"), Message(robot="d00", sim_t=0.0, data=None))
        host.later(None, comp.offer, Port("in"), Message(robot="d00", sim_t=0.1, data=None))  # waits in the mailbox
        assert entered.wait(30)
        stuck = host.settle(0.05)
        assert stuck.waited and not stuck.idle and host.busy()
        release.set()
        done = host.settle(30)
        assert done.idle and done.waited and comp.received == 2 and comp.dropped == 0
        again = host.settle(0.0)
        assert again.idle and not again.waited
    finally:
        release.set()
        host.close()
