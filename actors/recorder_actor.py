"""RecorderActor: the run's recorder, one per run, named ``aerodaas/<run>/recorder`` and placed on the driver's
edge node. Every other actor records through a :class:`~.recorder.RemoteRecorder` that batches its messages here
(frames as JPEG bytes, encoded by the sender); a :class:`~.recorder.RecorderService` writes the MCAP file and feeds
the live view. It outlives every other actor of the run: whatever dies, the driver still finishes the recording
with a ``/mission/result`` per drone.

It is also the run's memory of the drones: drone actors checkpoint here (:meth:`checkpoint`) and a restarted
drone actor reads its last checkpoint back (:meth:`last_checkpoint`). It is never restarted (``max_restarts=0``):
a new process could not reopen a half-written file.
"""
from __future__ import annotations

import os
import threading
from typing import Any

import ray

from aerodaas.runtime.specs import ActorSpec


@ray.remote(num_cpus=0, max_concurrency=16, max_restarts=0)
class RecorderActor:
    """``spec``: the recorder's :class:`~aerodaas.runtime.specs.ActorSpec` (``record``: the file and live view, or
    None; ``epoch_ns``), see the module docstring."""

    def __init__(self, spec: ActorSpec) -> None:
        self.spec = spec
        self.recorder: Any = None
        self._cp: dict[str, dict] = {}
        self._specs: dict[str, bytes] = {}
        self._wiring = b""
        self._specs_kept = threading.Event()
        self._set_up = threading.Event()  # setup() done (or failed): record() may hand messages on
        self._setup_lock = threading.Lock()
        self._lock = threading.Lock()
        self.received = 0

    def setup(self) -> dict:
        """Open the file and the live view. Raises what :class:`~.recorder.RecorderService` raises (a bad path,
        a busy live port)."""
        from aerodaas.actors.recorder import RecorderService

        rec = self.spec.record
        with self._setup_lock:
            try:
                if rec is not None and self.recorder is None:
                    from aerodaas.recording.schemas import register_json_schema

                    for name, js in rec.schemas.items():  # plug-in sensors' message schemas
                        register_json_schema(name, js)
                    self.recorder = RecorderService(rec.path, rec.meta, live=rec.live, max_pending_frames=64,
                                                    homes=rec.homes, declare=rec.declare)
            finally:
                self._set_up.set()
        live = getattr(self.recorder, "live", None)
        return {"host": "recorder", "pid": os.getpid(), "node_id": ray.get_runtime_context().get_node_id(),
                "live_url": live.url if live is not None else None, "components": []}

    def ping(self) -> int:
        return os.getpid()

    def record(self, batch: list) -> int:
        """Messages of another actor (:class:`~.recorder.RemoteRecorder`); returns how many were taken. The other
        actors set up while this one does: their first messages wait (at most 60 s) for the file to be open."""
        from aerodaas.actors.recorder import deliver

        self._set_up.wait(60.0)
        self.received += len(batch)
        return deliver(self.recorder, batch) if self.recorder is not None else 0

    def keep_specs(self, specs: dict[str, bytes], wiring: bytes) -> bool:
        """Keep every other actor's pickled spec and the run's pickled wiring (read by :meth:`spec_of`)."""
        self._specs, self._wiring = dict(specs), wiring
        self._specs_kept.set()
        return True

    def spec_of(self, host_id: str, wait_s: float = 60.0) -> tuple[bytes, bytes]:
        """(pickled spec, pickled wiring) of actor ``host_id``, waiting up to ``wait_s`` seconds for
        :meth:`keep_specs` (the driver starts every actor right after this one, without waiting). Raises KeyError
        for an unknown actor, TimeoutError when the specs never came."""
        if not self._specs_kept.wait(wait_s):
            raise TimeoutError(f"recorder: no specs after {wait_s:g} s (actor {host_id!r} asked)")
        return self._specs[host_id], self._wiring

    def checkpoint(self, robot_id: str, state: dict) -> bool:
        """Keep ``state`` as the newest checkpoint of ``robot_id`` (an older one, by vehicle time, is ignored)."""
        with self._lock:
            old = self._cp.get(robot_id)
            if old is None or state.get("seq", 0) >= old.get("seq", 0):
                self._cp[robot_id] = state
        return True

    def last_checkpoint(self, robot_id: str) -> dict | None:
        return self._cp.get(robot_id)

    def mission_result(self, robot_id: str, t_ns: int, result: dict) -> bool:
        """Record ``/mission/result`` for a drone whose actor could not (its node was lost)."""
        if self.recorder is not None:
            self.recorder.json("/mission/result", t_ns, {"robot": robot_id, **result}, "aerodaas.MissionResult")
            self.recorder.json(f"/{robot_id}/events", t_ns, {"robot": robot_id, "t": result.get("t", 0.0),
                                                             "event": "drone_actor_lost",
                                                             "error": result.get("error")}, "aerodaas.MissionEvent")
        return True

    def close(self) -> dict:
        """Finish the file; returns the per-topic message counts."""
        return self.recorder.close() if self.recorder is not None else {}

    def recording_report(self) -> dict:
        return self.recorder.report() if self.recorder is not None else {}

    def stats(self) -> dict:
        return {"_host": {"received": self.received, "errors": [], "error_count": 0}}
