"""What a component counts of the CPU its host spends for the user (``actors/analytics/component.py``
``process_cpu_s``): the analytics object's own calls, each once, measured on the thread that ran it. The drone
actor's whole account of a run is tested with the run itself (``tests/runtime/test_frames_taken.py``)."""
from __future__ import annotations

import time

import numpy as np

from aerodaas import Analytics


def _burn(cpu_s: float) -> None:
    """Spend ``cpu_s`` seconds of this thread's CPU."""
    t0 = time.thread_time()
    while time.thread_time() - t0 < cpu_s:
        pass


class Burner(Analytics):
    """Spends 0.03 CPU-s in every call; raises on the frame numbered 2 and in every batch call."""

    name = "burner"
    max_batch = 4

    def process(self, frame, meta):
        _burn(0.03)
        if meta.seq == 2:
            raise ValueError("frame 2 is refused")
        return {"ok": meta.seq}

    def process_batch(self, items):
        _burn(0.03)
        raise ValueError("no batches here")


def test_an_analytics_process_calls_are_counted_as_its_cpu_failed_ones_and_batch_retries_too():
    """``process_cpu_s``: the thread CPU of every call into the analytics object, once each: a call that returns,
    one that raises, a batch call that raises and the item-by-item calls that follow it (five calls of 0.03 CPU-s),
    and nothing of the hosting around them beyond a few milliseconds."""
    from aerodaas.actors.analytics.component import AnalyticsComponent
    from aerodaas.actors.data.plane import DataPlane
    from aerodaas.protocol.messages import FrameMsg, Port
    from aerodaas.model.types import CameraIntrinsics, FrameMeta, FramePose

    host = DataPlane("analytics/edge/burner#1", "edge", 0, workers=1)
    comp = host.add(AnalyticsComponent(host, "burner#1", "burner", Burner(), None, 0))
    host.publish = lambda src, envs, tok=None, inline=True: None
    k = CameraIntrinsics.from_hfov(16, 12, 78.0)

    def env(seq: int) -> FrameMsg:
        meta = FrameMeta(robot_id="d00", sensor_id="cam", seq=seq, capture_time=0.1 * seq, wall_time=time.time(),
                         intrinsics=k, pose=FramePose(position=(0.0, 0.0, 3.0), yaw=90.0))
        return FrameMsg(robot="d00", sim_t=0.1 * seq, data=np.zeros((12, 16, 3), np.uint8), meta=meta)

    try:
        comp.handle(Port("in"), env(1))
        comp.handle(Port("in"), env(2))
        comp.handle_batch([(Port("in"), env(3)), (Port("in"), env(4))])
    finally:
        host.close()
    assert (comp.processed, comp.failures) == (3, 1), (comp.processed, comp.failures)
    assert 0.15 <= comp.process_cpu_s < 0.17, comp.process_cpu_s
    assert comp.stats()["process_cpu_s"] == round(comp.process_cpu_s, 6)
