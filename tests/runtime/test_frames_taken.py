"""A camera makes only the frames something takes (``actors/sensors/camera.py`` ``CameraComponent``, the plan in
``aerodaas/runtime/dataflow.py``): a camera that no analytics subscribes to and nothing records is not built and
renders nothing; one that only the recorder takes renders at its ``properties.record_fps`` (default ``fps``: as
before); one an analytics takes renders at ``fps`` and the recorder keeps the frames at ``record_fps``. The due
frames nobody takes are counted as never made (``frames_not_made``), apart from the frames dropped at the camera.

Judged from the drone's report, the camera's stats, the run's summary, and the recording read with the ``mcap``
library against the run's vehicle time (the recorded odometry's span), never against the wall clock: the runs are
lock-step, so no frame is shed for a late clock and the recorder holds the clock instead of refusing frames."""
from __future__ import annotations

import pytest
from mcap.reader import make_reader

from aerodaas import Analytics, Environment
from aerodaas.actors.sensors.camera import CameraComponent
from aerodaas.backends.base import PoseSample
from aerodaas.bench.fleet import fleet_config
from aerodaas.config import parse_environment_config
from aerodaas.runtime.report import format_summary

pytestmark = pytest.mark.e2e

FPS, RECORD_FPS = 10.0, 2.0
#: frames a count may differ from vehicle time x rate by: the cameras' phases and the two ends of the run
TOLERANCE = 2.0


class Count(Analytics):
    """Takes every frame it is given, keeps none."""

    name = "count"

    def __init__(self) -> None:
        super().__init__()
        self.n = 0

    def process(self, frame, meta):
        self.n += 1
        return None


def _camera(sid: str, **extra) -> dict:
    return {"id": sid, "type": "camera",
            "properties": {"width": 160, "height": 120, "hfov_deg": 78, "fps": FPS, "pitch_deg": 90, **extra}}


def _env(cameras: list[dict], lockstep: bool = True) -> Environment:
    """One simulated drone ``d00`` with ``cameras``, hovering until the run's timeout; lock-step unless ``lockstep``
    is False (then real time: a lock-step clock that nothing consumes runs as fast as the CPU lets it, and a
    battery failsafe would end the hover before the timeout)."""
    cfg = fleet_config(1, fps=FPS, width=160, height=120)
    cfg["robots"][0]["sensors"] = cameras + [s for s in cfg["robots"][0]["sensors"] if s["type"] != "camera"]
    cfg["simulation"]["lockstep"] = lockstep
    return Environment(parse_environment_config(cfg))


def _recorded(path) -> dict[str, list[int]]:
    """Topic -> the log times (ns) of its messages, read with the mcap library."""
    out: dict[str, list[int]] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            out.setdefault(channel.topic, []).append(message.log_time)
    return out


@pytest.fixture(scope="module")
def recorded_run(ray_session, tmp_path_factory):
    """A recorded run of one drone with four cameras: ``seen`` (an analytics takes it, ``record_fps`` 2), ``rec``
    (only recorded, ``record_fps`` 2), ``all`` (only recorded, no ``record_fps``) and ``off`` (``record_fps`` 0,
    nothing takes it). Returns (result, topic -> log times, vehicle seconds the run's odometry spans)."""
    from aerodaas.actors.builtin.catalogue import BUILTIN_ACTORS
    from aerodaas.runtime.options import RunOptions

    env = _env([_camera("seen", record_fps=RECORD_FPS), _camera("rec", record_fps=RECORD_FPS), _camera("all"),
                _camera("off", record_fps=0)])
    count = Count()
    count.deploy(env.get_compute_resource_by_id("edge"), colocate=True)
    count.analyse(env.get_robot_by_id("d00").get_sensor_by_id("seen").get_data_stream())
    path = tmp_path_factory.mktemp("taken") / "taken.mcap"
    opts = RunOptions(progress=False, actors=BUILTIN_ACTORS, record=str(path), run_id="taken")
    res = env.start_mission(timeout=4.0, options=opts)
    rec = _recorded(path)
    odom = rec["/d00/odometry"]
    return res, rec, (odom[-1] - odom[0]) / 1e9


def _near(n: float, expected: float) -> bool:
    return abs(n - expected) <= TOLERANCE


def test_a_camera_nobody_takes_renders_nothing(ray_session, run_options):
    """Unrecorded, with no analytics on it: the plan builds no camera, the drone renders no frame."""
    run_options.run_id = "untaken"
    res = _env([_camera("cam")], lockstep=False).start_mission(timeout=2.0, options=run_options)
    rep = res.robots["d00"]
    assert rep["outcome"] == "timeout" and rep["ticks"] > 0, rep
    assert (rep["cameras"], rep["frames"], rep["frames_not_made"]) == (0, 0, 0), rep
    assert res.stats["d00"].get("cameras", {}) == {}, res.stats["d00"]


def test_a_recorded_camera_with_record_fps_0_that_nothing_takes_renders_nothing(recorded_run):
    res, rec, _ = recorded_run
    assert "off" not in res.stats["d00"]["cameras"], res.stats["d00"]["cameras"]
    assert res.robots["d00"]["cameras"] == 3
    assert not [t for t in rec if t.startswith("/d00/camera/off")], sorted(rec)


def test_a_camera_only_the_recorder_takes_renders_at_its_record_fps(recorded_run):
    res, rec, span_s = recorded_run
    assert span_s >= 3.0, span_s  # enough vehicle time to tell 2 frames/s from 10
    cam = res.stats["d00"]["cameras"]["rec"]
    assert cam["recorder_dropped"] == 0, cam  # the clock waited for the recorder: every frame made was recorded
    images = rec["/d00/camera/rec"]
    assert _near(len(images), span_s * RECORD_FPS), (len(images), span_s)
    assert _near((images[-1] - images[0]) / 1e9 * RECORD_FPS + 1, len(images)), images
    assert cam["frames"] == cam["ticks"] == len(images), cam  # made = recorded: none made for nobody
    assert _near(cam["frames_not_made"], span_s * (FPS - RECORD_FPS)), (cam, span_s)
    assert cam["dropped_at_camera"] == 0 and cam["record_skipped"] == 0, cam
    line = [x for x in format_summary(res).splitlines() if "camera rec:" in x]
    assert line and f"{cam['frames_not_made']} not made" in line[0], format_summary(res)


def test_a_camera_an_analytics_takes_renders_at_fps_and_is_recorded_at_record_fps(recorded_run):
    res, rec, span_s = recorded_run
    cam = res.stats["d00"]["cameras"]["seen"]
    analysed = res.stats["d00"]["analytics"][0]
    assert _near(cam["frames"], span_s * FPS), (cam, span_s)
    assert analysed["processed"] == cam["frames"], analysed  # lock-step: the analytics saw every frame made
    assert cam["frames_not_made"] == 0, cam
    images = rec["/d00/camera/seen"]
    assert _near(len(images), span_s * RECORD_FPS), (len(images), span_s)
    assert cam["record_skipped"] == cam["frames"] - len(images), cam
    assert "not made" not in [x for x in format_summary(res).splitlines() if "camera seen:" in x][0]


def test_a_recorded_camera_without_record_fps_renders_and_records_every_frame(recorded_run):
    res, rec, span_s = recorded_run
    cam = res.stats["d00"]["cameras"]["all"]
    assert _near(cam["frames"], span_s * FPS), (cam, span_s)
    assert len(rec["/d00/camera/all"]) == cam["frames"], cam
    assert cam["frames_not_made"] == cam["record_skipped"] == 0, cam


def test_the_drone_actor_accounts_its_cpu_and_what_the_user_brings_to_it(recorded_run):
    """The drone actor's CPU over its run (``_host.cpu``): its span in vehicle time, every thread's CPU, and of it
    the frame making of its three rendering cameras, its analytics' ``process`` calls and the JPEG encodes of the
    frames it recorded, each counted on the thread that ran it and only during the run (lock-step: every capture
    ends within it), so the cameras' and the analytics' own counters add up to the actor's."""
    res, _, span_s = recorded_run
    (cpu,) = [h["cpu"] for h in res.stats["_hosts"].values() if "flight_sim_s" in h.get("cpu", {})]
    assert cpu["drones"] == 1 and span_s - 0.5 <= cpu["flight_sim_s"] <= span_s + 2.0, (cpu, span_s)
    user = cpu["render_cpu_s"] + cpu["analytics_cpu_s"] + cpu["encode_cpu_s"]
    assert min(cpu["render_cpu_s"], cpu["analytics_cpu_s"], cpu["encode_cpu_s"]) > 0.0, cpu
    assert user < cpu["flight_cpu_s"], cpu  # the framework's own part is what is left, never negative
    cams = res.stats["d00"]["cameras"]
    assert set(cams) == {"seen", "rec", "all"}, cams
    assert abs(sum(c["render_cpu_s"] for c in cams.values()) - cpu["render_cpu_s"]) < 1e-5, (cams, cpu)
    assert abs(res.stats["d00"]["analytics"][0]["process_cpu_s"] - cpu["analytics_cpu_s"]) < 1e-5, cpu


@pytest.mark.parametrize("rate, said", [(12, "must be at most properties.fps (10), got 12"),
                                        (-1, "must be a finite number within [0, 240], got -1"),
                                        ("2", "got '2'")])
def test_a_record_fps_above_fps_or_not_a_rate_is_refused_naming_it(rate, said):
    """Before Ray starts: one error naming the robot, the sensor, the property and the value."""
    with pytest.raises(ValueError) as e:
        _env([_camera("cam", record_fps=rate)])
    assert "properties.record_fps" in str(e.value) and said in str(e.value), str(e.value)
    assert "'d00'" in str(e.value) and "'cam'" in str(e.value), str(e.value)


class _Plane:
    """A data plane that keeps the captures submitted to its pool (their ``record`` flag last) and has ``routes``."""

    def __init__(self, routes: dict) -> None:
        self.routes, self.submitted = routes, []

    def submit(self, fn, *args) -> None:
        self.submitted.append(args)


class _Recorder:
    def camera(self, *args) -> None:
        pass


def _ticks(plane: _Plane, late_at: int | None = None) -> CameraComponent:
    """100 due ticks of a 10 FPS camera recorded at 3 frames/s, each capture finishing before the next tick; the
    clock late at tick ``late_at``."""
    cam = CameraComponent(plane, "d/cam", "d", "cam", {"width": 16, "height": 12, "hfov_deg": 78, "fps": 10,
                                                       "pitch_deg": 90, "record_fps": 3}, None, None, _Recorder(), 0)
    for k in range(100):
        t = 0.05 + k / 10
        cam.try_capture(PoseSample(t, (0.0, 0.0, 10.0), 0.0), t, None, clock_late=k == late_at)
        if cam._busy.locked():
            cam._busy.release()  # the capture ran
    return cam


def test_the_recorders_frames_are_the_ones_made_when_nothing_else_takes_the_camera():
    """Over 9.9 s of ticks at 10 FPS: only the recorder's 30 frames (3/s) are made, the other 70 not; with a consumer
    routed from the camera all 100 are made and 30 of them are the recorder's. A due frame of the recorder shed for a
    late clock is made at the next tick (it counts as dropped, the tick after it is not a frame not made)."""
    alone = _Plane({})
    cam = _ticks(alone)
    assert (len(alone.submitted), cam.ticks, cam.frames_not_made, cam.dropped_at_camera) == (30, 30, 70, 0)
    assert all(a[-1] for a in alone.submitted)
    times = [a[2] for a in alone.submitted]
    assert all(abs((b - a) - 1 / 3) < 0.1 for a, b in zip(times, times[1:])), times  # one frame every 1/3 s
    taken = _Plane({"d/cam": [("count", "in", 1, None)]})
    cam = _ticks(taken)
    assert (len(taken.submitted), cam.ticks, cam.frames_not_made) == (100, 100, 0)
    assert sum(a[-1] for a in taken.submitted) == 30
    late = _Plane({})
    cam = _ticks(late, late_at=10)  # t = 1.05 s: a frame of the recorder's (its instants 0.05, 0.383, 0.717, 1.05)
    assert (cam.dropped_at_camera, cam.shed_late, cam.ticks - cam.dropped_at_camera) == (1, 1, 30)
    assert [a[2] for a in late.submitted][3] == pytest.approx(1.15)
