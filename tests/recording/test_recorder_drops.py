"""The frames a recorder refuses are in the recording, per image topic (``/run/recorder_drops``): a reader accounts
for every frame a camera took (beside two CPU burners 2 of 1,222 and 9 of 1,132 stream frames were refused by the
recorder actor's full queue and counted only in its own report)."""
from __future__ import annotations

import threading

import numpy as np

from aerodaas.actors.recording.recorder import RecorderService
from aerodaas.recording.reader import read_messages

from tests.recording.stalled_recorder import StalledPlane, StalledRecorder


def test_refused_frames_are_recorded_per_topic_and_the_written_ones_add_up(tmp_path):
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), max_pending_frames=2, flush_every_s=0.0)
    frame = np.zeros((48, 64, 3), np.uint8)
    offered = {"/d1/camera/a": 0, "/d1/camera/b": 0}
    refused = {"/d1/camera/a": 0, "/d1/camera/b": 0}
    gate = threading.Event()
    write = svc._write

    def busy_write(item):  # the writer is busy until every frame was offered: only 2 can wait, the rest is refused
        gate.wait(30)
        write(item)

    svc._write = busy_write
    for k in range(40):
        topic = "/d1/camera/a" if k % 4 else "/d1/camera/b"
        offered[topic] += 1
        if not svc.image(topic, 1_000_000 * (k + 1), frame, "d1/cam"):
            refused[topic] += 1
    gate.set()
    svc.close()
    written = {t: 0 for t in offered}
    drops = None
    for topic, _schema, _t, msg in read_messages(str(path)):
        if topic in written:
            written[topic] += 1
        elif topic == "/run/recorder_drops":
            drops = msg
    assert sum(refused.values()) == 38  # two waited for the writer
    assert drops is not None and drops["frames_dropped"] == refused and drops["total"] == sum(refused.values())
    assert all(written[t] == offered[t] - drops["frames_dropped"][t] for t in offered), (written, offered, drops)


def test_a_recording_without_images_has_no_drops_channel(tmp_path):
    path = tmp_path / "r.mcap"
    svc = RecorderService(str(path), flush_every_s=0.0)
    svc.json("/d1/events", 1, {"event": "x"}, "aerodaas.MissionEvent")
    svc.close()
    assert [t for t, *_ in read_messages(str(path))] == ["/d1/events", "/run/accounting"]


def test_a_stalled_recorder_actor_holds_a_bounded_number_of_frames_and_the_rest_are_dropped_and_counted(ray_session):
    """The recorder actor takes nothing (stalled): the producer sends at most ``max_in_flight_frames`` frames, keeps at
    most ``max_pending_frames`` more, and drops and counts the others; once the recorder answers again, every frame
    not dropped reaches it. Before, Ray's queue to a stopped recorder grew without bound (the 20 s stall of
    tests/runtime/test_faults.py lost frames in some runs and none in others, 2026-11-27)."""
    import time

    import ray

    from aerodaas.actors.recording.remote_recorder import RemoteRecorder

    recorder = ray.remote(max_concurrency=64)(StalledRecorder).remote()
    rec = RemoteRecorder(StalledPlane(recorder), period_s=0.01, max_pending_frames=20, max_in_flight_frames=8)
    frame = np.zeros((24, 32, 3), np.uint8)
    offered = 0
    for k in range(200):
        rec.image("/d1/camera/cam", 1_000_000 * (k + 1), frame, "d1/cam")
        offered += 1
        time.sleep(0.002)
    until = time.monotonic() + 60
    while rec.held_batches == 0 and time.monotonic() < until:  # the sending thread has met the bound
        time.sleep(0.05)
    in_flight = rec.frames_in_flight
    assert rec.held_batches > 0 and in_flight <= 8 + 20, (rec.held_batches, in_flight)
    assert rec.frames_dropped >= offered - 8 - 20 - 20, rec.frames_dropped  # one batch may exceed the bound
    ray.get(recorder.release.remote())
    rec.close(timeout_s=60)
    assert ray.get(recorder.recorded_frames.remote()) == offered - rec.frames_dropped
