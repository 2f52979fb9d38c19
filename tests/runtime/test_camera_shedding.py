"""Control before the camera: a drone actor's clock that is behind the wall clock does not render its cameras' due
frames (actors/host/assembly.py ``SHED_LATE_TICKS``; ``CameraComponent.try_capture``'s ``clock_late``), and says so in
the drone's report (``frames_shed_late``) and the run's summary."""
from __future__ import annotations

from aerodaas.actors.sensors.camera import CameraComponent
from aerodaas.backends.base import PoseSample
from aerodaas.runtime.report import format_summary
from tests.runtime.test_dataplane import FrameProbe, _env


class _Plane:
    """A data plane that only counts the captures submitted to its pool."""

    def __init__(self) -> None:
        self.submitted = 0
        self.routes: dict = {}

    def submit(self, fn, *args) -> None:
        self.submitted += 1

    def outlet_stats(self, cid: str) -> dict:
        return {}


def test_a_late_clock_sheds_a_pulled_cameras_frame_and_counts_it():
    plane = _Plane()
    cam = CameraComponent(plane, "cam", "uav", "cam1", {"width": 160, "height": 120, "hfov_deg": 78, "fps": 10,
                                                        "pitch_deg": 90}, None, None, None, 0)
    pose = PoseSample(1.0, (0.0, 0.0, 10.0), 0.0)
    assert not cam.try_capture(pose, 1.0, None, clock_late=True)
    assert (plane.submitted, cam.ticks, cam.dropped_at_camera, cam.shed_late) == (0, 1, 1, 1)
    assert cam.try_capture(pose, 1.1, None)  # on time again: the capture goes to the pool
    assert (plane.submitted, cam.ticks, cam.dropped_at_camera, cam.shed_late) == (1, 2, 1, 1)
    assert cam.stats()["shed_late"] == 1


def test_a_drone_actor_whose_clock_cannot_keep_up_renders_no_stale_frames(ray_session, run_options):
    """At 1,000 x real time no actor's clock keeps up with the wall clock (50 physics steps of a vehicle second in
    1 ms), whatever the machine's load: its camera's due frames are shed, counted and reported. (In lock-step the
    clock waits for nothing but the analytics, is never late, and sheds nothing: checked on the lock-step runs of
    ``tests/runtime/test_dataplane.py``.)"""
    env = _env(1)
    env.cfg.simulation.speedup = 1000.0
    probe = FrameProbe()  # a camera renders only for a consumer or a recording
    probe.deploy(env.get_compute_resource_by_id("edge"))
    probe.analyse(env.get_robot_by_id("d00").get_sensor_by_id("cam").get_data_stream())
    run_options.run_id = "shed1"
    late = env.start_mission(timeout=3.0, options=run_options)
    rep = late.robots["d00"]
    assert rep["frames"] > 0 and rep["frames_shed_late"] > 0, rep
    assert rep["frames_shed_late"] <= rep["frames_dropped_at_camera"] <= rep["frames"], rep
    assert "while the clock was late" in format_summary(late)
