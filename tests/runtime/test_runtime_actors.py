"""The Ray-native runtime under faults, each fault injected for real into a running mission:

* a drone actor killed mid-mission restarts, restores its checkpoint and resumes the mission from the waypoint it
  was heading to (every waypoint flown once, checked on the recording's odometry);
* an analytics actor killed mid-mission restarts; frames in flight count as failed; its navigation resumes;
* the node of a drone actor lost: that drone ends ``lost``, the other flies on, the recording is finished;
* a drone actor that dies for good under ``aerodaas run``: summary, finished recording, exit code 3, no traceback;
* the analytics scheduler's dispatcher actor killed mid-mission: the summary counts the tasks the recording holds;
* placement on a cluster of two edge nodes and a cloud node, from Ray's GCS: drone actors on their compute's node,
  a dispatcher per edge compute, the cloud executors on the cloud node.
"""
from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from aerodaas import AeroListData, Analytics, Environment, FollowAnalytics, PriorityQueue, Waypoint
from aerodaas.actors.drone.component import DroneComponent
from aerodaas.actors.drone.scheduler_component import SchedulerComponent
from aerodaas.config import parse_environment_config
from aerodaas.runtime.report import format_summary

from tests.conftest import needs_data

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.faults

WAYPOINTS = [(0.0, 8.0), (8.0, 8.0), (8.0, 0.0), (0.0, 0.0)]


def _env(fps: float = 5.0, restarts: int = 1) -> Environment:
    cfg = {"name": "faults", "actor_max_restarts": restarts, "actor_restart_timeout_s": 60.0,
           "robots": [{"id": "d00", "takeoff_altitude": 3.0,
                       "limits": {"max_speed": 2.0, "max_vertical_speed": 2.0, "max_acceleration": 3.0},
                       "sensors": [{"id": "cam", "type": "camera", "properties": {
                           "width": 160, "height": 120, "hfov_deg": 78, "fps": fps, "pitch_deg": 90}},
                                   {"id": "odom", "type": "odometry", "properties": {"rate_hz": 10}}]}],
           "world": {"ground": {"seed": 4, "metres_per_pixel": 0.05, "size_m": 60}},
           "simulation": {"speedup": 4.0}}
    return Environment(parse_environment_config(cfg))


def _survey(env: Environment, hover_s: float = 1.0):
    from aerodaas.schedulers import TrajectoryScheduler

    sched = TrajectoryScheduler(env)
    env.set_trajectory_scheduler(sched)
    drone = env.get_robot_by_id("d00")
    wps = [Waypoint(id=f"w{i}", x=x, y=y, z=3.0, hover_duration=hover_s) for i, (x, y) in enumerate(WAYPOINTS)]
    drone.navigate(sched.generate_navigation(PriorityQueue(AeroListData(wps), priority=2)))
    return drone, sched


def _messages(path: str, topic: str) -> list[dict]:
    """Messages of ``topic`` read with the mcap library's own reader (not ours)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [json.loads(m.data) for _, ch, m in make_reader(f).iter_messages(topics=[topic])]


def _until(attempt, tries: int = 3000, every_s: float = 0.1) -> bool:
    """Call ``attempt()`` every ``every_s`` seconds until it returns True (an exception counts as not yet: the
    actors are still starting, or restarting), at most ``tries`` times; returns whether it did."""
    for _ in range(tries):
        try:
            if attempt():
                return True
        except Exception:  # noqa: BLE001 - not started (or not back) yet
            pass
        time.sleep(every_s)
    return False


def _kill_when(actor_name: str, status_cid: str, ready, out: dict, no_restart: bool = False) -> threading.Thread:
    """A thread that waits for the actor, then for ``ready(status)``, then SIGKILLs it (``ray.kill``)."""
    import ray

    def once() -> bool:
        h = ray.get_actor(actor_name)
        st = ray.get(h.call.remote(status_cid, DroneComponent.status), timeout=10)
        if not ready(st):
            return False
        out["status"] = st
        out["wall"] = time.time()
        ray.kill(h, no_restart=no_restart)
        return True

    t = threading.Thread(target=_until, args=(once, 600), daemon=True)
    t.start()
    return t


def test_drone_actor_killed_mid_mission_restarts_and_resumes(ray_session, run_options, tmp_path):
    env = _env()
    _survey(env)
    run_options.run_id, run_options.record = "kill-drone", str(tmp_path / "kill.mcap")
    killed: dict = {}
    t = _kill_when("aerodaas/kill-drone/drone/d00", "d00/drone",
                   lambda st: st["visited"] >= 1 and st["state"] == "NAVIGATING", killed)
    res = env.start_mission(timeout=240, options=run_options)
    t.join(5)
    rep = res.robots["d00"]
    assert killed, "the drone actor was never killed"
    assert rep["actor_restarts"] == 1 and res.outcome == "success", (rep.get("error"), rep.get("outcome"))
    assert [w["id"] for w in rep["visited_waypoints"]] == ["w0", "w1", "w2", "w3"]  # each flown once, in order
    resumed = [e for e in rep["events"] if e["event"] == "resumed_after_restart"]
    assert len(resumed) == 1 and resumed[0]["heading_to"] in ("w1", "w2")
    assert resumed[0]["visited"] >= killed["status"]["visited"] - 1 >= 0
    # the recording (read with the mcap library): finished, the result says success, and the flight is continuous
    # through the restart (no jump back to home) and passes over every waypoint
    result = _messages(run_options.record, "/mission/result")
    assert [r["outcome"] for r in result] == ["success"]
    odom = [m["position"] for m in _messages(run_options.record, "/d00/odometry")]
    # no sample recorded twice: the restarted actor flies again from its checkpoint's time, and what it sends with a
    # stamp already recorded is dropped (mcap's reader: log times strictly increasing on the odometry channel)
    from mcap.reader import make_reader

    with open(run_options.record, "rb") as f:
        stamps = [m.log_time for _, _, m in make_reader(f).iter_messages(topics=["/d00/odometry"], log_time_order=False)]
    assert all(b > a for a, b in zip(stamps, stamps[1:])), [(a, b) for a, b in zip(stamps, stamps[1:]) if b <= a][:5]
    steps = [math.dist(a, b) for a, b in zip(odom, odom[1:])]
    assert max(steps) < 2.0, max(steps)
    for x, y in WAYPOINTS:
        assert min(math.dist((x, y, 3.0), p) for p in odom) < 0.6


class SlowCounter(Analytics):
    """Counts frames (one dict out per frame); takes ``delay_s`` per frame, so that frames are in flight."""

    name = "counter"

    def __init__(self, delay_s: float = 0.15) -> None:
        super().__init__()
        self.delay_s, self.n = delay_s, 0

    def process(self, frame, meta):
        time.sleep(self.delay_s)
        self.n += 1
        return {"n": self.n}


class AlwaysCar(Analytics):
    """One car box right of the image centre on every frame (a stub detector)."""

    name = "always_car"

    def process(self, frame, meta):
        from aerodaas.model.types import Detection

        h, w = frame.shape[:2]
        time.sleep(0.1)
        return [Detection(class_id=2, class_name="car", score=0.9, box=(0.7 * w, 0.45 * h, 0.8 * w, 0.55 * h))]


@pytest.mark.parametrize("lockstep,transport", [(False, "channel"), (True, "channel"), (True, "ray")],
                         ids=["realtime", "lockstep", "lockstep-ray"])
def test_analytics_actor_killed_mid_mission_restarts_and_navigation_resumes(ray_session, run_options, tmp_path,
                                                                            lockstep, transport):
    """A frame analytics' actor is killed mid-mission; Ray restarts it and navigation resumes. In real time the
    frames sent meanwhile are lost (counted failed); under lock-step the simulated clock waits for the restarted
    actor: at most the frames in flight at the kill are lost (over Ray calls not even those: a call refused while
    the actor restarts is sent again), every later one reaches it."""
    import ray

    env = _env(fps=10.0)
    env.cfg.simulation.lockstep = lockstep
    env.cfg.same_node_transport = transport
    drone, sched = _survey(env, hover_s=30.0)
    edge = env.get_compute_resource_by_id("edge")
    det = AlwaysCar()
    det.deploy(edge)  # its own actor
    follow = FollowAnalytics(target_classes=["car"], confirm_hits=1, lost_after=1e9, max_speed=1.5)
    follow.deploy(edge, colocate=True)
    sched.add_navigation(PriorityQueue(follow.analyse(det.analyse(drone.get_sensor_by_id("cam").get_data_stream())),
                                       priority=1))
    run_options.run_id, run_options.record = "kill-analytics", str(tmp_path / "ka.mcap")
    killed: dict = {}
    name = "aerodaas/kill-analytics/analytics/edge/always_car#1"
    counts: dict = {}

    def go() -> None:
        counts["before"] = _kill_after_frames("kill-analytics", name, restart=True)
        killed["wall"] = time.time()
        d = ray.get_actor("aerodaas/kill-analytics/drone/d00")
        for _ in range(600):  # navigation resumes: new commands applied after the restart
            try:
                s = ray.get(d.call.remote("d00/scheduler", SchedulerComponent.stats), timeout=10)
                if s["frames_with_latency"] >= counts["before"] + 5:
                    counts["after"] = s["frames_with_latency"]
                    ray.get(d.call.remote("d00/drone", DroneComponent.end_mission, "ended"), timeout=10)
                    return
            except Exception:  # noqa: BLE001
                pass
            time.sleep(0.1)

    t = threading.Thread(target=go, daemon=True)
    t.start()
    res = env.start_mission(timeout=180, options=run_options)
    t.join(5)
    assert killed and "after" in counts, (killed, counts, res.outcome)
    assert res.robots["d00"]["outcome"] == "ended" and not res.robots["d00"].get("error")
    cam = res.stats["d00"]["cameras"]["cam"]
    (outlet,) = cam["outlets"]
    assert outlet["transport"] == transport
    if lockstep:  # the clock held: nothing but what was in flight at the kill is lost, the send waited instead
        assert outlet["failed"] <= 2 and outlet["held"] >= 1 and not outlet.get("lost"), outlet
        assert not res.analytics_lost and res.outcome == "ended"
        times = _log_times(run_options.record)
        frames, dets = times["/d00/camera/cam"], times["/d00/always_car/detections"]
        # the frames after the restart were analysed: all but those counted failed at the kill and the one frame
        # whose cascade was still open when the test ended the mission (recorded, its detection not yet made)
        assert len(dets) >= len(frames) - outlet["failed"] - 1, (len(frames), len(dets), outlet)
        # simulated time did not run on past the outage without analytics: no hole in the detections' sim time
        # wider than the frame(s) in flight at the kill (frames every 0.1 s)
        gaps = np.diff(np.asarray(dets, np.int64)) / 1e9
        assert gaps.max() <= 0.3 + 1e-6, gaps
    else:
        assert outlet["failed"] >= 1, outlet  # the frame(s) in flight when the actor died, and those sent meanwhile
    assert res.stats["d00"]["analytics"][0]["processed"] > 0  # counted by the restarted actor
    assert res.stats["_hosts"]["analytics/edge/always_car#1"].get("error_count", 0) == 0


def test_dispatcher_actor_killed_mid_mission_the_summary_counts_the_recordings_tasks(ray_session, run_options,
                                                                                     tmp_path):
    """The analytics scheduler's dispatcher actor is killed mid-mission and Ray restarts it: the restarted one
    counts its tasks from zero, the recording does not. The summary's scheduler headline (tasks, per state,
    utility) is what the recording's task records hold (read back with aerodaas.recording.reader), more than the
    restarted dispatcher counted, and that count is named beside it."""
    import ray

    from aerodaas.recording.reader import read_messages

    env = _env(fps=5.0)
    drone, sched = _survey(env, hover_s=30.0)
    det = AlwaysCar()  # 0.1 s per frame, scheduled per frame on the edge compute's dispatcher
    det.deploy(env.get_compute_resource_by_id("edge"))
    det.analyse(drone.get_sensor_by_id("cam").get_data_stream())
    env.set_analytics_scheduler("DEMS", {"always_car": {"deadline_ms": 300, "edge_ms": 100, "cloud_ms": 120,
                                                        "benefit": 100, "edge_cost": 1, "cloud_cost": 20}})
    run_options.run_id, run_options.record = "kill-dispatcher", str(tmp_path / "kd.mcap")
    name = "aerodaas/kill-dispatcher/dispatcher/edge"
    seen: dict = {}

    def submitted() -> int:
        return ray.get(ray.get_actor(name).stats.remote(), timeout=10)["_analytics_scheduler"]["submitted"]

    def pid() -> int:
        return ray.get(ray.get_actor(name).ping.remote(), timeout=10)

    def go() -> None:
        def kill() -> bool:
            if submitted() < 15:
                return False
            seen["before"], seen["pid"] = submitted(), pid()
            ray.kill(ray.get_actor(name), no_restart=False)
            return True

        def restarted_and_counting() -> bool:  # a new process, which counts from 0
            return pid() != seen["pid"] and submitted() >= 10

        if _until(kill, 600) and _until(restarted_and_counting, 600):
            seen["after"] = submitted()
            d = ray.get_actor("aerodaas/kill-dispatcher/drone/d00")
            ray.get(d.call.remote("d00/drone", DroneComponent.end_mission, "ended"), timeout=10)

    t = threading.Thread(target=go, daemon=True)
    t.start()
    res = env.start_mission(timeout=180, options=run_options)
    t.join(5)
    assert "after" in seen, (seen, res.outcome)
    assert res.robots["d00"]["outcome"] == "ended" and not res.robots["d00"].get("error")
    records = [m for _, schema, _, m in read_messages(run_options.record, topics=["/d00/always_car/tasks"])
               if schema == "aerodaas.AnalyticsTask"]
    states: dict[str, int] = {}
    for r in records:
        states[r["state"]] = states.get(r["state"], 0) + 1
    utility = sum(r["utility"] for r in records)
    assert all(r["scheduler"] == "DEMS" and r["utility"] is not None for r in records)
    tally = res.recording_accounting["tasks"]["DEMS"]
    assert tally["tasks"] == len(records) and tally["states"] == states
    assert tally["utility"] == pytest.approx(utility)
    # the restarted dispatcher's own count; the records of the first one's tasks are in the recording too (those
    # it held or had not yet handed to the recorder when it was killed are not: they reached no terminal state)
    own = res.stats["analytics_scheduler"]["submitted"]
    assert seen["after"] <= own < len(records), (seen, own, len(records))
    line = next(ln for ln in format_summary(res).splitlines() if ln.startswith("  analytics scheduler DEMS"))
    assert f": {len(records)} tasks (from the recording)" in line, line
    assert f"utility {utility:.0f}," in line and f"its dispatchers counted {own} (since their last restart)" in line
    for state, n in states.items():
        assert f"{state} {n}" in line, line


@needs_data
def test_real_yolox_detector_killed_under_lockstep_in_the_vehicle_tracking_app(ray_session, run_options, data_env,
                                                                              tmp_path, capfd):
    """``apps/vehicle_tracking.py`` as shipped (lock-step on, its detector, aerial_nano, in its own actor): once the detector actor
    has analysed 15 frames (its own count), it is SIGKILLed by its exact name. Ray restarts it (a new process
    answers to the same name), the simulated clock waits for it, the drone's mission succeeds (the run's outcome is
    recording_lost when frames in flight were lost, and the file lacks exactly those), the drone actor is not
    restarted nor said to be, and the restarted detector analyses the rest of the flight (the recording, read with
    mcap's reader: at most the frames in flight at the kill lack detections)."""
    from aerodaas.runtime.driver import run_file

    import ray

    from aerodaas.actors.analytics.component import AnalyticsComponent

    run_options.run_id, run_options.record = "kill-yolox", str(tmp_path / "yolox.mcap")
    name = "aerodaas/kill-yolox/analytics/edge/detector#1"
    seen: dict = {}

    def kill_at_15() -> bool:
        h = ray.get_actor(name)
        n = ray.get(h.call.remote("detector#1", AnalyticsComponent.stats), timeout=10)["processed"]
        if n < 15:
            return False
        seen["before"], seen["pid"] = n, ray.get(h.ping.remote(), timeout=10)
        ray.kill(h, no_restart=False)
        return True

    def answers_again() -> bool:  # the same name answers from a new process while the mission goes on
        pid = ray.get(ray.get_actor(name).ping.remote(), timeout=10)
        if pid != seen["pid"]:
            seen["pid_after"] = pid
        return pid != seen["pid"]

    def kill() -> None:
        if _until(kill_at_15):
            _until(answers_again)

    t = threading.Thread(target=kill, daemon=True)
    t.start()
    res = run_file(str(ROOT / "apps" / "vehicle_tracking.py"), run_options)[-1]
    t.join(5)
    err = capfd.readouterr().err
    assert seen, "the detector never analysed 15 frames"
    # the mission flew on; the frames in flight at the kill were offered to the detector and never answered: the
    # recording's accounting counts them lost on the detections channel (recording_lost, never success with a hole)
    lost = (res.recording_accounting or {}).get("lost", {})
    assert set(lost) <= {"/quadrotor_base/detector/detections"}, lost
    assert res.outcome == ("recording_lost" if lost else "success"), \
        (res.outcome, lost, res.robots["quadrotor_base"].get("error"), err[-2000:])
    assert res.robots["quadrotor_base"]["outcome"] == "success", res.robots["quadrotor_base"].get("error")
    assert res.robots["quadrotor_base"].get("actor_restarts", 0) == 0 and "drone actor" not in err, err[-2000:]
    assert seen.get("pid_after"), "the detector actor did not answer again from a new process"
    det = res.stats["_hosts"]["analytics/edge/detector#1"]
    assert det.get("error_count", 0) == 0, det
    (outlet,) = res.stats["quadrotor_base"]["cameras"]["cam1"]["outlets"]
    assert outlet["failed"] <= 2 and outlet["held"] >= 1 and not outlet.get("lost"), outlet
    assert not res.analytics_lost
    times = _log_times(run_options.record)
    frames, dets = times["/quadrotor_base/camera/cam1"], times["/quadrotor_base/detector/detections"]
    missing = [i for i, t in enumerate(frames) if t not in set(dets)]
    summary = format_summary(res)  # the death is reported as the detector's, with what it cost
    assert re.search(r"frames to detector#1: its actor died and was restarted \(1 reconnect\(s\)\); [0-2] frame\(s\) "
                     r"in flight lost, [1-9]\d* held \(lock-step\)", summary), summary
    print("frames without detections:", missing, "of", len(frames), "; the detector had analysed", seen["before"])
    # one hole, at the kill: the frames in the channel's 2 slots and the detections the dead process had not yet
    # handed to the recorder (it batches every 0.1 s of wall time: ~5 frames at this run's pace), each counted lost
    assert len(missing) <= 12 and missing == list(range(missing[0], missing[0] + len(missing))), missing
    assert sum(lost.values()) == len(missing), (lost, missing)
    # the restarted process's own count: it analysed the rest of the flight
    (stats,) = [a for a in res.stats["quadrotor_base"]["analytics"] if a.get("name") == "detector"]
    assert stats["processed"] >= len(frames) - missing[-1] - 1 > 0, (stats, len(frames), missing)


@pytest.mark.parametrize("transport", ["channel", "ray"])
def test_lockstep_analytics_actor_not_back_is_reported_lost(ray_session, run_options, tmp_path, transport):
    """Lock-step, the analytics actor killed for good (no restart): the clock holds at most
    ``actor_restart_timeout_s``, then the mission flies on and the run reports the analytics lost (not ``ok``)."""

    env = _env(fps=10.0)
    env.cfg.simulation.lockstep = True
    env.cfg.actor_restart_timeout_s = 3.0
    env.cfg.same_node_transport = transport
    drone, sched = _survey(env, hover_s=1.0)
    edge = env.get_compute_resource_by_id("edge")
    det = AlwaysCar()
    det.deploy(edge)
    follow = FollowAnalytics(target_classes=["car"], confirm_hits=1, lost_after=1e9, max_speed=1.5)
    follow.deploy(edge, colocate=True)
    sched.add_navigation(PriorityQueue(follow.analyse(det.analyse(drone.get_sensor_by_id("cam").get_data_stream())),
                                       priority=1))
    run_options.run_id, run_options.record = f"lost-analytics-{transport}", str(tmp_path / "la.mcap")
    name = f"aerodaas/lost-analytics-{transport}/analytics/edge/always_car#1"
    killed: dict = {}

    def go() -> None:
        _kill_after_frames(f"lost-analytics-{transport}", name, restart=False)
        killed["ok"] = True

    t = threading.Thread(target=go, daemon=True)
    t.start()
    res = env.start_mission(timeout=180, options=run_options)
    t.join(5)
    assert killed, res.outcome
    (outlet,) = res.stats["d00"]["cameras"]["cam"]["outlets"]
    assert outlet["transport"] == transport and outlet["lost"] is True, outlet
    assert res.analytics_lost == ["always_car#1"] and res.outcome == "analytics_lost" and not res.ok, \
        (res.outcome, res.analytics_lost)
    assert "analytics LOST: always_car#1" in format_summary(res)


def _kill_after_frames(run: str, actor: str, restart: bool, frames: int = 5) -> int:
    """Once drone d00's scheduler of run ``run`` has had ``frames`` analysed frames, kill actor ``actor`` (Ray
    restarts it when ``restart``); returns the count seen then. Polls every 0.1 s (at most 600 times)."""
    import ray

    for _ in range(600):
        try:
            d = ray.get_actor(f"aerodaas/{run}/drone/d00")
            s = ray.get(d.call.remote("d00/scheduler", SchedulerComponent.stats), timeout=10)
            if s["frames_with_latency"] >= frames:
                ray.kill(ray.get_actor(actor), no_restart=not restart)
                return s["frames_with_latency"]
        except Exception:  # noqa: BLE001 - the actors are still starting
            pass
        time.sleep(0.1)
    raise TimeoutError(f"run {run}: never {frames} analysed frames")


def _log_times(path: str) -> dict[str, list[int]]:
    """Topic -> log times (ns) of its messages, read with the mcap library's own reader."""
    from mcap.reader import make_reader

    out: dict[str, list[int]] = {}
    with open(path, "rb") as f:
        for _, ch, m in make_reader(f).iter_messages(log_time_order=True):
            out.setdefault(ch.topic, []).append(m.log_time)
    return out


def _run(args: list[str], timeout: float, env: dict | None = None) -> subprocess.CompletedProcess:
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout, env=e)


def _result(p: subprocess.CompletedProcess) -> dict:
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")), None)
    assert line is not None, (p.returncode, p.stdout[-3000:], p.stderr[-3000:])
    return json.loads(line[len("RESULT "):])


@pytest.mark.cluster
def test_node_of_a_drone_actor_lost(tmp_path):
    p = _run(["tests/cluster/cluster_runtime_app.py", "node_loss", str(tmp_path)], timeout=600)
    r = _result(p)
    assert "Traceback" not in p.stderr, p.stderr[-3000:]
    assert r["killed"].get("node"), r
    assert r["robots"]["d01"]["outcome"] == "lost" and "lost" in r["robots"]["d01"]["error"]
    assert r["robots"]["d00"]["outcome"] == "success" and r["robots"]["d00"]["visited"] == 3  # flew on
    assert r["outcome"] == "lost" and "lost" in r["summary"]
    results = {m["robot"]: m["outcome"] for m in _messages(r["recording"], "/mission/result")}
    assert results == {"d00": "success", "d01": "lost"}  # the recording is finished and says so


@pytest.mark.cluster
def test_placement_on_two_edge_nodes_and_a_cloud_node(tmp_path):
    p = _run(["tests/cluster/cluster_runtime_app.py", "placement", str(tmp_path)], timeout=600)
    r = _result(p)
    run = [a for a in r["actors"] if (a["name"] or "").startswith("aerodaas/place/")]
    site = {a["name"].split("aerodaas/place/")[1]: (a["labels"].get("tier"), a["labels"].get("aerodaas/site"))
            for a in run}
    for i in range(6):  # drones d00, d02, d04 fly from edge-a; d01, d03, d05 from edge-b
        assert site[f"drone/d{i:02d}"] == ("edge", "ab"[i % 2]), site
    assert site["dispatcher/edge-a"] == ("edge", "a") and site["dispatcher/edge-b"] == ("edge", "b")
    clouds = [v for k, v in site.items() if k.startswith("cloud-analytics")]
    assert clouds and all(v[0] == "cloud" for v in clouds), site
    assert site["recorder"][0] == "edge"
    assert r["outcome"] == "success" and r["scheduler"]["submitted"] > 0, r


def test_drone_actor_lost_for_good_under_aerodaas_run_exits_3_with_summary_and_recording(tmp_path):
    app = tmp_path / "lost_app.py"
    rec = tmp_path / "lost.mcap"
    env_file = tmp_path / "env.json"
    env_file.write_text(json.dumps({
        "name": "lost", "actor_max_restarts": 0,
        "robots": [{"id": "d00", "takeoff_altitude": 3.0,
                    "sensors": [{"id": "odom", "type": "odometry", "properties": {"rate_hz": 10}}]}],
        "simulation": {"speedup": 4.0}}))
    app.write_text(f'''
import threading, time
import ray
from aerodaas import *

env = Environment({str(env_file)!r})
drone = env.get_robot_by_id("d00")
sched = TrajectoryScheduler(env)
env.set_trajectory_scheduler(sched)
wps = [Waypoint(id=f"w{{i}}", x=6.0 * i, y=0.0, z=3.0, hover_duration=2.0) for i in range(4)]
drone.navigate(sched.generate_navigation(PriorityQueue(AeroListData(wps), priority=2)))

def kill(robot):
    def go():
        time.sleep(3.0)
        ray.kill(ray.get_actor("aerodaas/lost/drone/d00"))
    threading.Thread(target=go, daemon=True).start()

drone.on_mission_start(kill)
drone.start_mission()
''')
    p = _run(["-m", "aerodaas.cli", "run", str(app), "--record", str(rec), "--quiet"], timeout=300,
             env={"AERODAAS_RUN_ID": "lost"})
    assert p.returncode == 3, (p.returncode, p.stdout[-2000:], p.stderr[-2000:])
    assert "Traceback" not in p.stderr and "Traceback" not in p.stdout, p.stderr[-3000:]
    assert "mission outcome: lost" in p.stdout and "drone actor" in p.stdout
    assert [m["outcome"] for m in _messages(str(rec), "/mission/result")] == ["lost"]
