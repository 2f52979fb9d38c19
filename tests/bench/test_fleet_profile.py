"""``aerodaas bench fleet --profile``'s measuring parts: the per-thread CPU and wakes read from /proc, the
py-spy stacks classified into components, CPU apportioned between them, PSS split by mapping, the bare actor beside
the fleet (on the pytest worker's shared Ray session)."""
from __future__ import annotations

import os
import threading
import time

import numpy as np

from aerodaas.bench.bare_actor import BareActor
from aerodaas.bench.fleet_profile import Component, ThreadCpu, attribute, bare_row, classify_stack, \
    parse_pyspy_raw, process_counts, smaps_pss, thread_cpu, thread_wakes
from aerodaas.bench.procs import ray_processes

#: stacks as py-spy 0.4 writes them (``--threads --format raw``), taken from a drone actor of the fleet benchmark
RENDER = ("Thread._bootstrap (threading.py:1002);_worker (concurrent/futures/thread.py:83);DataPlane._guard "
          "(actors/data/plane.py:282);CameraComponent._capture (actors/sensors/camera.py:199);CameraComponent._produce "
          "(actors/sensors/camera.py:241);RenderedFrames.frame_at (actors/sensors/frame_sources.py:55);World.render "
          "(aerodaas/sim/world.py:165)")
ANALYSE = ("_worker (concurrent/futures/thread.py:83);CameraComponent._capture (actors/sensors/camera.py:204);"
           "DataPlane.publish (actors/data/plane.py:300);AnalyticsComponent._run (actors/analytics/component.py:90);"
           "FrameExposure.process (aerodaas/bench/fleet_analytics.py:29)")
ENCODE = ("Thread.run (threading.py:982);RemoteRecorder._loop (actors/recording/remote_recorder.py:216);RemoteRecorder._send "
          "(actors/recording/remote_recorder.py:197);encode_frame (actors/data/frames.py:49)")
MAIN = "<module> (ray/_private/workers/default_worker.py:323);Worker.main_loop (ray/_private/worker.py:1069)"
PHYSICS = ("DroneActor.run (actors/host/drone_actor.py:38);ActorAssembly.run (actors/host/assembly.py:270);DroneComponent.step "
           "(actors/drone/component.py:320);SimBackend.step (aerodaas/backends/sim.py:70);SimVehicle.step "
           "(aerodaas/sim/vehicle.py:90)")
CONTROL = ("DroneActor.run (actors/host/drone_actor.py:38);ActorAssembly.run (actors/host/assembly.py:288);"
           "ActorAssembly._control_due (actors/host/assembly.py:315);DroneComponent.control_tick (actors/drone/component.py:340)")


def test_stacks_go_to_the_innermost_concern():
    assert classify_stack(RENDER) is Component.CAMERA
    assert classify_stack(ANALYSE) is Component.ANALYTICS  # the analytics runs inside the camera's publish
    assert classify_stack(ENCODE) is Component.RECORD_ENCODE  # the encode inside the recorder's send
    assert classify_stack(MAIN) is Component.RAY_PYTHON
    assert classify_stack(PHYSICS) is Component.PHYSICS
    assert classify_stack(CONTROL) is Component.CONTROL
    assert classify_stack("ActorAssembly.run (actors/host/assembly.py:266)") is Component.CLOCK


HOSTING = ("_worker (concurrent/futures/thread.py:83);CameraComponent._capture (actors/sensors/camera.py:204);"
           "AnalyticsComponent.handle (actors/analytics/component.py:76);AnalyticsComponent._process_one "
           "(actors/analytics/component.py:131);collecting (aerodaas/analytics/contract.py:88)")
USER = ("AnalyticsComponent.handle (actors/analytics/component.py:76);AnalyticsComponent._process_one "
        "(actors/analytics/component.py:132);MyDetector.process (my_app.py:12);_mean (numpy/_core/_methods.py:118)")
SCHEDULE = ("ActorAssembly.run (actors/host/assembly.py:356);_capture_due (actors/host/assembly.py:90);"
            "CameraComponent.try_capture (actors/sensors/camera.py:160);DataPlane.submit (actors/data/plane.py:263);"
            "ThreadPoolExecutor.submit (concurrent/futures/thread.py:176)")
IDLE = "Thread._bootstrap (threading.py:1002);Thread.run (threading.py:982);_worker (concurrent/futures/thread.py:81)"


def test_the_users_analytics_is_apart_from_the_framework_hosting_it():
    assert classify_stack(USER) is Component.ANALYTICS  # whatever the analytics' class and what it calls
    assert classify_stack(HOSTING) is Component.ANALYTICS_HOST
    assert classify_stack(IDLE) is Component.POOL
    assert classify_stack(SCHEDULE) is Component.DATA_PLANE  # the clock hands the capture to the pool


def test_raw_output_counts_samples_per_native_thread_and_component():
    text = "\n".join([f"thread (4242): aerodaas-drone/d00_0;{RENDER} 30",
                      f"thread (4242): aerodaas-drone/d00_0;{ANALYSE} 10",
                      f"thread (4100): MainThread;{MAIN} 5", "py-spy> a line that is not a sample", ""])
    assert parse_pyspy_raw(text) == {4242: {Component.CAMERA: 30, Component.ANALYTICS: 10},
                                     4100: {Component.RAY_PYTHON: 5}}


def test_a_threads_waits_take_no_share_of_what_it_ran():
    text = "\n".join([f"thread (4242): aerodaas-drone/d00_0;{RENDER} 30", f"thread (4242): aerodaas-drone/d00_0;{IDLE} 70",
                      f"thread (4100): MainThread;{MAIN} 5", f"thread (4300): Dummy-1;{IDLE} 9"])
    assert parse_pyspy_raw(text) == {4242: {Component.CAMERA: 30}, 4100: {Component.RAY_PYTHON: 5},
                                     4300: {Component.POOL: 9}}


def test_cpu_is_split_by_each_threads_own_samples_and_unsampled_threads_by_name():
    before = {1: ThreadCpu(1, "ray::DroneActor", 10.0), 2: ThreadCpu(2, "ray::DroneActor", 1.0),
              3: ThreadCpu(3, "worker.io", 2.0)}
    after = {1: ThreadCpu(1, "ray::DroneActor", 14.0), 2: ThreadCpu(2, "ray::DroneActor", 1.5),
             3: ThreadCpu(3, "worker.io", 2.25), 4: ThreadCpu(4, "ray::DroneActor", 0.5)}  # 4: born in the window
    samples = {1: {Component.CAMERA: 3, Component.ANALYTICS: 1}}
    got = attribute(before, after, samples, "ray::DroneActor")
    assert got == {Component.CAMERA: 3.0, Component.ANALYTICS: 1.0, Component.NATIVE_UNNAMED: 1.0,
                   Component.RAY_CORE: 0.25}
    assert attribute(before, after, None, "ray::DroneActor")[Component.NATIVE_UNNAMED] == 5.0  # no profiler


def test_thread_cpu_reads_the_kernels_count_for_each_thread():
    native: dict = {}
    spent, release = threading.Event(), threading.Event()

    def burn() -> None:
        native["tid"] = threading.get_native_id()
        t0 = time.thread_time()
        while time.thread_time() - t0 < 0.3:  # 0.3 s of this thread's own CPU, however loaded the machine
            sum(range(1000))
        native["cpu"] = time.thread_time()
        spent.set()
        release.wait(120)  # alive until the main thread has read /proc

    th = threading.Thread(target=burn)
    th.start()
    assert spent.wait(120)
    got = thread_cpu(os.getpid())
    release.set()
    th.join()
    assert os.getpid() in got  # the main thread, whose tid is the pid
    # the kernel's utime + stime of that thread, in clock ticks (10 ms): at least what the thread measured itself
    assert got[native["tid"]].cpu_s >= native["cpu"] - 0.02


def test_pss_rows_add_up_to_the_kernels_total(tmp_path):
    big = np.ones(20 * 2**20, dtype=np.uint8)  # 20 MiB of anonymous memory, touched
    path = tmp_path / "ground.bin"
    np.ones(8 * 2**20, dtype=np.uint8).tofile(path)
    mapped = np.memmap(path, dtype=np.uint8, mode="r")
    assert int(mapped.sum()) == 8 * 2**20  # every page read
    rows = smaps_pss(os.getpid())
    with open(f"/proc/{os.getpid()}/smaps_rollup") as f:
        total = next(int(line.split()[1]) for line in f if line.startswith("Pss:")) / 1024
    assert abs(sum(rows.values()) - total) < 4.0, (rows, total)
    assert rows["anonymous (Python objects, malloc arenas, thread stacks)"] >= 20.0
    assert rows["system libraries and other files"] >= 7.5  # the mapped file, not in a package or the stdlib
    assert any(k == "package numpy" for k in rows)
    del big, mapped


def test_thread_wakes_counts_each_time_a_thread_blocks():
    """A thread that sleeps 30 times blocks (and is woken) at least 30 times: the process's count, read before the
    thread exits (an exited thread's count is gone), grows by that."""
    counted: dict = {}
    release = threading.Event()

    def sleeper() -> None:
        for _ in range(30):
            time.sleep(0.001)
        counted["after"] = thread_wakes(os.getpid())
        release.set()

    counted["before"] = thread_wakes(os.getpid())
    th = threading.Thread(target=sleeper)
    th.start()
    assert release.wait(60)
    th.join()
    assert counted["after"] - counted["before"] >= 30, counted


def test_the_bare_actor_is_measured_apart_from_the_nodes_processes(ray_session):
    """The bench's floor: an idle BareActor in the run's Ray, listed among the node's processes unless excluded,
    its CPU, wakes, threads and PSS read over a window (Ray's own threads wake it even when nobody calls it)."""
    import ray

    actor = BareActor.remote()
    try:
        pid = ray.get(actor.pid.remote(), timeout=120)
        assert pid in {p.pid for p in ray_processes()}
        assert pid not in {p.pid for p in ray_processes(exclude=(pid,))}
        c0 = process_counts(pid)
        time.sleep(1.0)
        c1 = process_counts(pid)
        row = bare_row(pid, c0, c1, window=1.0, per=2.0)
        assert row["pid"] == pid and row["threads"] >= 2 and row["wakes_per_s"] > 0, row
        assert row["cpu_s_per_drone_per_sim_s"] == round((c1[0] - c0[0]) / 2.0, 4)
        assert 20.0 < row["pss_mb"] < 200.0, row  # a Ray worker: the interpreter and Ray, nothing of the framework
    finally:
        ray.kill(actor)
    assert process_counts(None) is None
