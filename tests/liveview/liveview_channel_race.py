"""Run by tests/liveview/test_liveview_npm_client.py in a subprocess of its own (it pins this whole process to one CPU).

A LiveServer with Foxglove's npm client connected; then one thread, at SCHED_IDLE on the same CPU as a busy-loop
process, creates 30 channels with 3 messages each, as the recorder's thread creates ``/uav/mission/plan`` mid-run.
SCHED_IDLE makes the thread lose the CPU as soon as it wakes another one, i.e. right after the SDK has queued a new
channel's advertisement. Prints ``{"statuses": [...], "counts": {topic: n}, "topics": [...]}`` as JSON.

usage: python liveview_channel_race.py NODE COUNT_CHANNELS_MJS
"""
from __future__ import annotations

import json
import multiprocessing
import os
import subprocess
import sys
import threading
import time

from aerodaas.liveview.server import LiveServer
from aerodaas.recording.writer import RecordedMessage


def _busy_until(t_end: float) -> None:
    while time.time() < t_end:
        pass


def main(node: str, script: str) -> None:
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})  # before the server starts: its threads, the busy loop and node share the CPU
    srv = LiveServer("127.0.0.1:0")
    schema = ("probe.Msg", "jsonschema", b'{"type": "object"}')
    srv.publish(RecordedMessage("/seed", *schema, "json", 1, b"{}"))
    client = subprocess.Popen([node, script, srv.url, "90"], cwd=os.path.dirname(script), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    t_end = time.monotonic() + 60
    while srv.subscriptions < 1 and time.monotonic() < t_end:
        time.sleep(0.05)
    hog = multiprocessing.get_context("fork").Process(target=_busy_until, args=(time.time() + 40,), daemon=True)
    hog.start()
    topics = [f"/uav{i}/mission/plan" for i in range(30)]

    def create() -> None:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        for i, topic in enumerate(topics):
            for j in range(3):
                srv.publish(RecordedMessage(topic, *schema, "json", 1000 * i + j + 2, b"{}"))
            time.sleep(0.002)

    th = threading.Thread(target=create)
    th.start()
    th.join(60)
    hog.terminate()
    srv.stop(linger_s=1.0)
    out, _ = client.communicate(timeout=60)
    got = json.loads(out)
    print(json.dumps({"statuses": got["statuses"], "counts": got["counts"], "topics": topics}))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
