"""The driver's watch on the run's recorder actor (``aerodaas.runtime.recorder_watch``): once the drones are done,
``settle`` asks the recorder once more, so that a restart after the watch's last poll is counted, said on the
console and followed by the live view served again where the first recorder bound it, before the run ends."""
from __future__ import annotations

from types import SimpleNamespace as NS

import ray

from aerodaas.runtime.recorder_watch import RecorderWatch

LIVE = "127.0.0.1:4321"


@ray.remote(num_cpus=0)
class _Recorder:
    """The recorder actor's calls the watch makes; :meth:`restart` plays Ray's restart (a new process id, a new
    segment, no live view served yet)."""

    def __init__(self) -> None:
        self.pid, self.served, self.kept = 100, [], 0

    def status(self) -> dict:
        first = self.pid == 100
        return {"pid": self.pid, "segment": "run.mcap" if first else "run.1.mcap", "last_t_ns": None,
                "live_url": f"ws://{LIVE}" if first else None}

    def restart(self) -> None:
        self.pid = 101

    def keep_specs(self, specs: dict, wiring: bytes) -> None:
        self.kept += 1

    def serve_live(self, address: str) -> str:
        self.served.append(address)
        return f"ws://{address}"

    def calls(self) -> dict:
        return {"served": self.served, "kept": self.kept}


def _plan() -> NS:
    """A run's plan as far as the watch reads it: the recorder's spec, and what ``recorder_specs`` pickles."""
    recorder = NS(spec=NS(epoch_ns=0, record=NS(path="run.mcap")), tier="edge")
    return NS(actors={"recorder": recorder}, routes=dict, location=dict, peer_names=dict, channel_key=None)


def test_a_restart_after_the_last_poll_is_seen_when_the_drones_are_done(ray_session, capsys):
    rec = _Recorder.remote()
    try:
        watch = RecorderWatch(rec, _plan(), period_s=3600.0)
        watch.settle()  # the first process: nothing lost
        assert watch.restarts == 0 and watch.live_url == f"ws://{LIVE}"
        ray.get(rec.restart.remote())
        watch.poll()  # asks (its first question), but the answer is not there yet: nothing seen
        watch.settle()
        assert watch.restarts == 1
        assert ray.get(rec.calls.remote()) == {"served": [LIVE], "kept": 1}  # specs again, live view where it was
        assert "recording lost" in capsys.readouterr().err
        watch.settle()  # the same process again: no second restart, nothing served twice
        assert watch.restarts == 1 and ray.get(rec.calls.remote())["served"] == [LIVE]
    finally:
        ray.kill(rec)
