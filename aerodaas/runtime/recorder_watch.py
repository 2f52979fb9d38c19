"""The driver's watch on the run's recorder actor (:class:`RecorderWatch`): a recorder that dies mid-run is
restarted by Ray into a new segment file (:mod:`aerodaas.actors.recording.actor`); the driver notices the new
process, says "recording lost (recorded up to at least t = ...)" at once (the summary gives the segment's exact end),
and gives the new recorder the other actors' specs again (a drone or analytics actor restarted later reads its spec
there)."""
from __future__ import annotations

import sys
import time
from typing import Any

__all__ = ["RecorderWatch", "recorder_specs"]


def recorder_specs(plan: Any) -> tuple[dict[str, bytes], bytes]:
    """(host id -> pickled spec of every actor but the recorder, pickled wiring): what the recorder keeps for
    restarted actors (:meth:`aerodaas.actors.recording.actor.RecorderActor.keep_specs`)."""
    from ray import cloudpickle  # lazy: heavy ray

    wiring = {"routes": plan.routes(), "location": plan.location(),
              "tiers": {h: a.tier for h, a in plan.actors.items()}, "peers": plan.peer_names(),
              "channel_key": plan.channel_key}
    return ({hid: cloudpickle.dumps(a.spec) for hid, a in plan.actors.items() if hid != "recorder"},
            cloudpickle.dumps(wiring))


class RecorderWatch:
    """Poll the recorder actor's :meth:`status` (at most every ``period_s`` seconds, never blocking the caller).
    ``restarts`` counts the recorder processes that replaced a dead one; ``lost_at_s`` the sim time (s) of the
    last message the driver knew recorded before each loss."""

    def _path(self) -> str | None:
        rec = self.plan.actors["recorder"].spec.record
        return rec.path if rec is not None else None

    def __init__(self, recorder: Any, plan: Any, period_s: float = 1.0) -> None:
        self.recorder, self.plan, self.period_s = recorder, plan, period_s
        self.epoch_ns = plan.actors["recorder"].spec.epoch_ns
        self.pid: int | None = None
        self.last_t_ns: int | None = None
        self.restarts = 0
        self.lost_at_s: list[float | None] = []
        self.live_url: str | None = None  # the live view's URL as the recorder reported it (ws://HOST:PORT)
        self._ref = None
        self._asked = 0.0

    def poll(self) -> None:
        """Look at the recorder's last answer and ask again; never raises, never waits."""
        import ray  # lazy: heavy ray

        if self.recorder is None:
            return
        try:
            if self._ref is not None:
                ready, _ = ray.wait([self._ref], timeout=0)
                if not ready:
                    return
                ref, self._ref = self._ref, None
                try:
                    st = ray.get(ref)
                except Exception:  # noqa: BLE001 - dead or restarting: the next answer tells
                    st = None
                if st is not None:
                    self._seen(st)
            if time.monotonic() - self._asked >= self.period_s:
                self._asked = time.monotonic()
                self._ref = self.recorder.status.remote()
        except Exception:  # noqa: BLE001 - a watch never ends the run
            self._ref = None

    def settle(self, timeout_s: float = 10.0) -> None:
        """The drones are done: ask the recorder once more and wait for its answer (at most ``timeout_s`` seconds,
        wall), so that a restart in the last poll period is seen before the run ends (its "recording lost" line, the
        count in ``restarts``) and the live view of a port chosen at start is served again, awaited as well, before
        the run's last messages (the mission result). Never raises: a recorder that does not answer is left to the
        run's end, which reports it."""
        import ray  # lazy: heavy ray

        if self.recorder is None:
            return
        self._ref = None
        try:
            again = self._seen(ray.get(self.recorder.status.remote(), timeout=timeout_s))
            if again is not None:
                ray.get(again, timeout=timeout_s)
        except Exception:  # noqa: BLE001 - a watch never ends the run
            pass

    def _seen(self, st: dict) -> Any:
        """Take the recorder's status ``st``; a new process is a restart. Returns the ObjectRef of the call that
        serves the live view again, or None."""
        if self.pid is None or st["pid"] == self.pid:
            self.pid = st["pid"]
            self.last_t_ns = st.get("last_t_ns") or self.last_t_ns
            self.live_url = st.get("live_url") or self.live_url
            return None
        self.pid = st["pid"]
        self.restarts += 1
        at = None if self.last_t_ns is None else (self.last_t_ns - self.epoch_ns) / 1e9
        self.lost_at_s.append(at)
        where = "" if at is None else f" (recorded up to at least t = {at:.1f} s; the summary gives the exact time)"
        print(f"aerodaas: recording lost{where}: the recorder actor died and was restarted; recording continues "
              f"in {st.get('segment')} (join the segments with `aerodaas recover "
              f"{self._path()}`)", file=sys.stderr, flush=True)
        self.last_t_ns = st.get("last_t_ns")
        try:
            self.recorder.keep_specs.remote(*recorder_specs(self.plan))
            if self.live_url and not st.get("live_url"):  # the live view where the first recorder bound it
                return self.recorder.serve_live.remote(self.live_url.split("://", 1)[-1])
        except Exception:  # noqa: BLE001
            pass
        return None
