"""A simulated run's clock waits for a recorder that falls behind instead of dropping frames
(``simulation.recorder_hold_s``, :class:`aerodaas.actors.recording.remote_recorder.FrameHold`): the recorder's ``image`` call,
made on the clock's thread, waits for room up to the hold's budget; past it, frames are dropped and counted as
before. Real vehicles and video streams never wait (the run's hold is 0)."""
from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pytest

from aerodaas.actors.recording.recorder import RecorderService
from aerodaas.recording.reader import read_messages

from tests.recording.stalled_recorder import StalledPlane, StalledRecorder

APPS = Path(__file__).resolve().parents[2] / "apps"
FRAME = np.zeros((24, 32, 3), np.uint8)


class _Producer(threading.Thread):
    """Offers ``n`` frames to ``rec`` (as a camera on the clock's thread does); ``started`` counts calls begun."""

    def __init__(self, rec, n: int) -> None:
        super().__init__(daemon=True)
        self.rec, self.n, self.started, self.refused = rec, n, 0, 0

    def run(self) -> None:
        for k in range(self.n):
            self.started += 1
            if not self.rec.image("/d1/camera/cam", 1_000_000 * (k + 1), FRAME, "d1/cam"):
                self.refused += 1


def _blocked_writer(svc: RecorderService) -> threading.Event:
    """Make ``svc``'s writer thread wait (a recorder starved of CPU) until the returned event is set."""
    gate = threading.Event()
    write = svc._write

    def busy_write(item):
        gate.wait(120)
        write(item)

    svc._write = busy_write
    return gate


def _frames_in(path: Path) -> int:
    return sum(1 for topic, *_ in read_messages(str(path)) if topic == "/d1/camera/cam")


def test_a_held_recorder_service_makes_the_camera_wait_and_loses_no_frame(tmp_path):
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), max_pending_frames=2, flush_every_s=0.0, hold_s=120.0)
    gate = _blocked_writer(svc)
    prod = _Producer(svc, 12)
    prod.start()
    prod.join(timeout=3.0)
    assert prod.is_alive() and prod.started < 12, "the camera did not wait for the recorder"
    # the wait in progress is seen by any thread (the drone's status) before it is over
    assert svc.hold.held_s == 0.0 and svc.hold.spent_s() > 0.0
    gate.set()
    prod.join(timeout=120)
    svc.close()
    assert not prod.is_alive() and prod.refused == 0 and svc.frames_dropped == 0
    assert _frames_in(path) == 12
    assert svc.hold.spent_s() == svc.hold.held_s > 0.0


def test_past_its_budget_the_hold_drops_and_counts_as_before(tmp_path):
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), max_pending_frames=2, flush_every_s=0.0, hold_s=0.3)
    gate = _blocked_writer(svc)
    prod = _Producer(svc, 12)
    prod.start()
    prod.join(timeout=120)  # the writer is still blocked: only the budget lets the camera go on
    assert not prod.is_alive()
    assert prod.refused >= 12 - 2 - 1 and svc.frames_dropped == prod.refused
    assert svc.hold.held_s >= 0.3
    gate.set()
    svc.close()
    assert _frames_in(path) == 12 - prod.refused


def test_without_a_hold_frames_are_dropped_at_once(tmp_path):
    svc = RecorderService(str(tmp_path / "r.mcap"), max_pending_frames=2, flush_every_s=0.0)
    gate = _blocked_writer(svc)
    prod = _Producer(svc, 12)
    prod.start()
    prod.join(timeout=120)
    assert not prod.is_alive() and prod.refused >= 9 and svc.hold.held_s == 0.0
    gate.set()
    svc.close()


def test_a_stalled_recorder_actor_holds_the_camera_and_every_frame_arrives(ray_session):
    import ray

    from aerodaas.actors.recording.remote_recorder import RemoteRecorder

    recorder = ray.remote(max_concurrency=64)(StalledRecorder).remote()
    rec = RemoteRecorder(StalledPlane(recorder), period_s=0.01, max_pending_frames=10, max_in_flight_frames=4,
                         hold_s=300.0)
    prod = _Producer(rec, 60)
    prod.start()
    prod.join(timeout=5.0)
    assert prod.is_alive() and prod.started < 60, "the camera did not wait for the stalled recorder"
    ray.get(recorder.release.remote())
    prod.join(timeout=240)
    rec.close(timeout_s=120)
    assert not prod.is_alive() and prod.refused == 0 and rec.frames_dropped == 0
    assert ray.get(recorder.recorded_frames.remote()) == 60
    assert rec.hold.held_s > 0.0


def _env(backend: str = "sim", stream: bool = False, hold: float | None = None):
    from aerodaas import Environment
    from aerodaas.config import parse_environment_config

    d = json.loads((APPS / "farm_survey.json").read_text())
    r = d["robots"][0]
    r["backend"] = backend
    if backend == "mavlink":
        r["mavlink"] = {"connection": "udpin:127.0.0.1:14550"}
    if stream:
        r["sensors"] = [{"id": "cam1", "type": "camera", "properties": {"width": 640, "height": 480,
                                                                        "source": "rtsp://127.0.0.1:8554/cam"}}]
    if hold is not None:
        d["simulation"]["recorder_hold_s"] = hold
    d["simulation"]["speedup"] = 1
    return Environment(parse_environment_config(d))


@pytest.mark.parametrize("backend, stream, want", [("sim", False, 120.0), ("mavlink", False, 0.0),
                                                   ("sim", True, 0.0)])
def test_only_a_run_wholly_on_the_simulator_may_hold_its_clock(backend, stream, want):
    from aerodaas.runtime.preflight import simulation_for

    env = _env(backend, stream)
    assert simulation_for(env, env.get_env_robots(), None).recorder_hold_s == want


def test_the_hold_is_the_users_and_bad_values_are_named():
    from aerodaas.config import ConfigError
    from aerodaas.runtime.options import RunOptions
    from aerodaas.runtime.preflight import simulation_for

    env = _env(hold=7.5)
    assert simulation_for(env, env.get_env_robots(), None).recorder_hold_s == 7.5
    assert simulation_for(env, env.get_env_robots(), RunOptions(recorder_hold_s=0.0)).recorder_hold_s == 0.0
    with pytest.raises(ConfigError, match="--recorder-hold: -1"):
        simulation_for(env, env.get_env_robots(), RunOptions(recorder_hold_s=-1.0))
    with pytest.raises(Exception, match="recorder_hold_s"):
        _env(hold=-3)
