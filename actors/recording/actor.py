"""RecorderActor: the run's recorder, one per run, named ``aerodaas/<run>/recorder`` and placed on the driver's
edge node. Every other actor records through a :class:`~aerodaas.actors.recording.remote_recorder.RemoteRecorder` that batches its messages here
(frames as JPEG bytes, encoded by the sender); a :class:`~aerodaas.actors.recording.recorder.RecorderService` writes the MCAP file and feeds
the live view. It outlives every other actor of the run: whatever dies, the driver still finishes the recording
with a ``/mission/result`` per drone.

It is also the run's memory of the drones: drone actors checkpoint here (:meth:`checkpoint`) and a restarted
drone actor reads its last checkpoint back (:meth:`last_checkpoint`).

If its process dies (SIGKILL, a native crash), Ray restarts it (``max_restarts=RECORDER_MAX_RESTARTS``). A new
process cannot append to the dead one's half-written file, so the restarted recorder opens the next *segment*
(``RUN.mcap`` -> ``RUN.1.mcap``, :mod:`aerodaas.recording.segments`) at once, in its constructor, and finishes the
previous segment in the background (:func:`aerodaas.recording.recover.recover_mcap`, so it is readable). What was
in flight is lost: :meth:`recording_report` then holds ``segments`` and ``losses`` (``recorded_until_ns`` of the
previous segment, ``resumed_at_ns``), the run says "recording lost at t = ..." and ends with exit code 4.
``aerodaas recover RUN.mcap`` joins the segments. The driver gives a restarted recorder the specs again
(:meth:`keep_specs`); checkpoints come back with the drones' next ones.
"""
from __future__ import annotations

import dataclasses
import os
import threading
import time
from typing import Any
import warnings

import ray

from aerodaas.protocol.messages import ProducerLedger, SealedCheckpoint
from aerodaas.actors.recording.checkpoints import CheckpointStore
from aerodaas.protocol.specs import ActorSpec
from aerodaas.recording.recover import recover_mcap
from aerodaas.recording.segments import message_time_range, next_segment, remove_stale_segments, segment_path
from aerodaas.recording.task_tally import TaskTally, tally_recording


#: how often Ray restarts a dead recorder actor (each restart opens a new segment file)
RECORDER_MAX_RESTARTS = 3


@ray.remote(num_cpus=0, max_concurrency=16, max_restarts=RECORDER_MAX_RESTARTS)
class RecorderActor:
    """``spec``: the recorder's :class:`~aerodaas.protocol.specs.ActorSpec` (``record``: the file and live view, or
    None; ``epoch_ns``), see the module docstring."""

    def __init__(self, spec: ActorSpec) -> None:
        self.spec = spec
        self.recorder: Any = None
        self.checkpoints = CheckpointStore()
        self._specs: dict[str, bytes] = {}
        self._wiring = b""
        self._specs_kept = threading.Event()
        self._set_up = threading.Event()  # setup() done (or failed): record() may hand messages on
        self._setup_lock = threading.Lock()
        self._lock = threading.Lock()
        self._ledgers: dict[str, ProducerLedger] = {}  # producer host id -> its counts (the largest seen)
        self._incarnations: dict[str, int] = {}  # producer host id -> the last incarnation handed out (ledger_of)
        self.received = 0
        self.segments: list[str] = []
        self.losses: list[dict] = []
        self._finishing: threading.Thread | None = None
        self.live_error: str | None = None  # a restarted recorder that could not serve the live view again
        self._forward: Any = None  # a node recorder's LiveForwarder to the driver's recorder (per-node recording)

        with warnings.catch_warnings():  # Ray's property reads its own deprecated ``actor_id`` internally
            warnings.simplefilter("ignore")
            reconstructed = ray.get_runtime_context().was_current_actor_reconstructed
        if reconstructed:
            self._restart_segment()

    def _restart_segment(self) -> None:
        """This process replaces a recorder that died: record into the next segment from now on and finish the
        previous one (the dead process's, unfinished) in a background thread. Every earlier segment ended with a
        death of this actor: each is one of ``losses`` (a second death was reported alone before: the first one's
        loss lived in the process that died second)."""
        rec = self.spec.record
        if rec is None or not rec.path:
            self._set_up.set()
            return
        from aerodaas.actors.recording.recorder import RecorderService  # lazy: heavy cv2, mcap, numpy, protobuf, pydantic

        k, path = next_segment(rec.path)
        prev = segment_path(rec.path, k - 1)
        self.segments = [str(segment_path(rec.path, i)) for i in range(k + 1)]
        for i in range(k - 1):  # deaths before the last one: their segments were finished by the next recorder
            self.losses.append(_earlier_loss(segment_path(rec.path, i), segment_path(rec.path, i + 1)))
        loss = {"segment": str(prev), "next_segment": str(path), "recorded_until_ns": None, "resumed_at_ns": None,
                "previous_finished": False}
        self.losses.append(loss)
        try:
            self.recorder = RecorderService(str(path), rec.meta, max_pending_frames=64, homes=rec.homes,
                                            declare=rec.declare, live_access=rec.live_access, hold_s=self._hold_s(),
                                            json_schemas=rec.schemas)
        except OSError as e:
            loss["error"] = f"{type(e).__name__}: {e}"
        finally:
            self._set_up.set()
        if rec.live and self.recorder is not None:
            from aerodaas.liveview.server import parse_address  # lazy: heavy cv2, mcap, numpy, protobuf, pydantic

            host, port = parse_address(rec.live)
            if port:  # a fixed port: serve there again at once (port 0: the driver's watch gives the bound one)
                threading.Thread(target=self.serve_live, args=(f"{host}:{port}",), name="aerodaas-live-again",
                                 daemon=True).start()

        def finish_previous() -> None:
            try:
                recover_mcap(prev)
                first, loss["recorded_until_ns"], _ = message_time_range(prev)
                loss["previous_finished"] = True
                if len(self.losses) > 1 and self.losses[-2].get("resumed_at_ns") is None:
                    self.losses[-2]["resumed_at_ns"] = first  # the death before: recorded again from prev's start
            except Exception as e:  # noqa: BLE001 - reported; `aerodaas recover` can try again
                loss["finish_error"] = f"{type(e).__name__}: {e}"

        self._finishing = threading.Thread(target=finish_previous, name="aerodaas-finish-segment", daemon=True)
        self._finishing.start()

    def setup(self) -> dict:
        """Open the file and the live view. Raises what :class:`~aerodaas.actors.recording.recorder.RecorderService` raises (a bad path,
        a busy live port)."""
        rec = self.spec.record
        with self._setup_lock:
            try:
                if rec is not None and self.recorder is None:
                    from aerodaas.actors.recording.recorder import (  # lazy: heavy cv2, mcap, numpy, pydantic
                        RecorderService)

                    if rec.path:  # segments of an earlier run to the same file would be joined to this one
                        remove_stale_segments(rec.path)
                        self.segments = [str(rec.path)]
                    self.recorder = RecorderService(rec.path, rec.meta, live=rec.live, max_pending_frames=64,
                                                    homes=rec.homes, declare=rec.declare, hold_s=self._hold_s(),
                                                    live_access=rec.live_access,
                                                    json_schemas=rec.schemas)  # plug-in sensors' message schemas
            finally:
                self._set_up.set()
            if self.spec.record_remote and self.recorder is not None and self._forward is None:
                self._forward_live()
        live = getattr(self.recorder, "live", None)
        return {"host": "recorder", "pid": os.getpid(), "node_id": ray.get_runtime_context().get_node_id(),
                "live_url": live.url if live is not None else None, "components": []}

    def _forward_live(self) -> None:
        """A node's recorder of a run with a live view (``spec.record_remote`` names the driver's recorder,
        :mod:`aerodaas.runtime.node_recorders`): every message written is also sent to the driver's recorder,
        whose actor name is this one's without its last part (``aerodaas/<run>/recorder/<compute>`` ->
        ``aerodaas/<run>/recorder``), for its live view (:class:`~aerodaas.actors.recording.live_forward.LiveForwarder`)."""
        from aerodaas.actors.recording.live_forward import LiveForwarder  # lazy: heavy cv2, mcap, numpy, protobuf, pydantic

        main = ray.get_actor(ray.get_runtime_context().get_actor_name().rsplit("/", 1)[0])
        self._forward = LiveForwarder(main)
        self.recorder.rec.add_sink(self._forward)

    def publish_live(self, msgs: list) -> int:
        """Messages a node's recorder wrote (:class:`~aerodaas.recording.writer.RecordedMessage`), shown on this
        recorder's live view as if written here (not recorded here: the node's file has them); returns how many
        were published (0 without a live view)."""
        live = getattr(self.recorder, "live", None)
        if live is None:
            return 0
        for m in msgs:
            live.publish(m)
        return len(msgs)

    def serve_live(self, address: str, attempts: int = 10, every_s: float = 0.5) -> str | None:
        """Serve the live view on ``address`` (HOST:PORT) unless this process already does: a recorder restarted
        after its first process died serves the run's live view again where the first one did, so a Foxglove
        client reconnects to the same URL. Binding is retried ``attempts`` times every ``every_s`` seconds; returns
        the URL, or None (with ``live_error`` set) when it cannot bind."""
        rec = self.recorder
        if rec is None:
            return None
        err = None
        for _ in range(max(1, attempts)):
            try:
                with self._setup_lock:
                    return rec.attach_live(address)
            except (RuntimeError, ValueError) as e:
                err = f"{type(e).__name__}: {e}"
            time.sleep(every_s)
        self.live_error = err
        return None

    def _hold_s(self) -> float:
        """How long in all (wall s) the recorder's ``image`` may wait for room in a simulated run: while a ``record``
        call waits, its sender's frames wait too, and so does the sender's simulated clock
        (:class:`~aerodaas.actors.recording.remote_recorder.FrameHold`)."""
        return float(self.spec.sim.get("recorder_hold_s", 0.0))

    def ping(self) -> int:
        return os.getpid()

    def status(self) -> dict:
        """``{"pid", "restarted": bool, "segment": the file written now, "last_t_ns", "live_url"}`` (the driver polls
        it to see a restart)."""
        rec = self.recorder
        live = getattr(rec, "live", None)
        return {"pid": os.getpid(), "restarted": bool(self.losses),
                "segment": self.segments[-1] if self.segments else None,
                "last_t_ns": getattr(rec, "last_t_ns", None), "live_url": live.url if live is not None else None}

    def record(self, batch: list, ledger: ProducerLedger | None = None) -> int:
        """Messages of another actor (:class:`~aerodaas.actors.recording.remote_recorder.RemoteRecorder`) and its counts so far (``ledger``,
        kept: :meth:`ledger_of`); returns how many were taken. The other actors set up while this one does: their
        first messages wait (at most 60 s) for the file to be open."""
        if ledger is not None:
            self.keep_ledger(ledger)
        self._set_up.wait(60.0)
        self.received += len(batch)
        if self.recorder is None:
            return 0
        from aerodaas.actors.recording.recorder import deliver  # lazy: heavy cv2, mcap, numpy, protobuf, pydantic

        return deliver(self.recorder, batch)

    def keep_ledger(self, ledger: ProducerLedger) -> None:
        """Keep the largest count per key of ``ledger.producer`` (batches may arrive out of order)."""
        with self._lock:
            old = self._ledgers.get(ledger.producer)
            self._ledgers[ledger.producer] = ledger if old is None else old.merged(ledger)

    def ledger_of(self, producer: str) -> ProducerLedger:
        """Actor ``producer``'s counts so far, as its batches said (empty for one never heard of), with the
        incarnation number of the process asking (:attr:`ProducerLedger.incarnation`): one more than any this
        actor handed out or saw in a batch of that producer, so a restarted producer's number differs from the
        dead process's even when the dead one's last batch is still on its way. A producer asks once per process,
        before its first batch; it counts on from here, so its sequence numbers never restart from 0."""
        with self._lock:
            kept = self._ledgers.get(producer) or ProducerLedger(producer, {})
            incarnation = max(self._incarnations.get(producer, 0), kept.incarnation) + 1
            self._incarnations[producer] = incarnation
            return dataclasses.replace(kept, incarnation=incarnation)

    def ledgers(self) -> list[ProducerLedger]:
        """Every producer's counts."""
        with self._lock:
            return list(self._ledgers.values())

    def keep_specs(self, specs: dict[str, bytes], wiring: bytes) -> bool:
        """Keep every other actor's pickled spec and the run's pickled wiring (read by :meth:`spec_of`)."""
        self._specs, self._wiring = dict(specs), wiring
        self._specs_kept.set()
        return True

    def spec_of(self, actor_id: str, wait_s: float = 60.0) -> tuple[bytes, bytes]:
        """(pickled spec, pickled wiring) of actor ``host_id``, waiting up to ``wait_s`` seconds for
        :meth:`keep_specs` (the driver starts every actor right after this one, without waiting). Raises KeyError
        for an unknown actor, TimeoutError when the specs never came."""
        if not self._specs_kept.wait(wait_s):
            raise TimeoutError(f"recorder: no specs after {wait_s:g} s (actor {actor_id!r} asked)")
        return self._specs[actor_id], self._wiring

    def checkpoint(self, robot_id: str, sealed: SealedCheckpoint) -> bool:
        """Keep ``sealed`` as the newest checkpoint of ``robot_id``, never unpickled here
        (:meth:`~aerodaas.actors.recording.checkpoints.CheckpointStore.keep`: False when it goes with a waypoint
        queue not kept here; the drone actor then sends the queue again)."""
        return self.checkpoints.keep(robot_id, sealed)

    def last_checkpoint(self, robot_id: str) -> SealedCheckpoint | None:
        """The newest checkpoint of ``robot_id``, sealed (``.open()`` it) with the queue it goes with, or None."""
        return self.checkpoints.last(robot_id)

    def mission_result(self, robot_id: str, t_ns: int, result: dict) -> bool:
        """Record ``/mission/result`` for a drone whose actor could not (its node was lost)."""
        if self.recorder is not None:
            self.recorder.json("/mission/result", t_ns, {"robot": robot_id, **result}, "aerodaas.MissionResult")
            self.recorder.json(f"/{robot_id}/events", t_ns, {"robot": robot_id, "t": result.get("t", 0.0),
                                                             "event": "drone_actor_lost",
                                                             "error": result.get("error")}, "aerodaas.MissionEvent")
        return True

    def close(self) -> dict:
        """Finish the file; returns the per-topic message counts (of this segment). The file ends with the run's
        accounting (:meth:`~aerodaas.actors.recording.recorder.RecorderService.close`: the producers' counts, the messages in the earlier
        segments, the task records of every segment tallied per analytics scheduler) and, when the run lost
        anything — this recorder replaced a dead one, or a numbered message is in no segment — ``/run/result``
        ``{"outcome": "recording_lost", "losses": [...], "lost": {topic: n}}`` (stamped after the last message
        written so far): the recording, joined or not, never reads as a success (the drones' ``/mission/result``
        say how each mission went; :func:`aerodaas.recording.reader.summarize` lets the run's outcome win)."""
        if self._finishing is not None:
            self._finishing.join(120.0)
        if self.recorder is None:
            return {}
        if self.losses and self.losses[-1].get("resumed_at_ns") is None:  # this segment's first message
            self.losses[-1]["resumed_at_ns"] = getattr(self.recorder, "first_t_ns", None)
        counts, tasks = self._earlier_segments()
        out = self.recorder.close(ledgers=self.ledgers(), recorded_before=counts, run_losses=list(self.losses),
                                  tasks_before=tasks)
        if self._forward is not None:  # after the file's last message: the live view sees the node's whole run
            self._forward.close()
        return out

    def _earlier_segments(self) -> tuple[dict[str, int], Any]:
        """What this run's earlier segments (finished by now) hold, each file summarized once: topic -> messages,
        and their task records tallied per scheduler (a :class:`~aerodaas.recording.task_tally.TaskTally`). An
        unreadable segment counts 0 messages (they count as lost) and adds the task records read before the
        error."""
        from aerodaas.recording.reader import summarize_mcap  # lazy: heavy mcap

        out: dict[str, int] = {}
        tally = TaskTally()
        for seg in self.segments[:-1]:
            try:
                channels = summarize_mcap(seg)["channels"]
                for c in channels:
                    out[c["topic"]] = out.get(c["topic"], 0) + c["count"]
                tally_recording(tally, seg, channels)
            except Exception:  # noqa: BLE001 - unreadable: its messages are not there to count
                continue
        return out, tally

    def recording_report(self) -> dict:
        """:meth:`~aerodaas.actors.recording.recorder.RecorderService.report` plus ``segments`` (the files of this run, in
        order) and ``losses`` (one per recorder restart: ``segment``, ``recorded_until_ns``, ``next_segment``,
        ``resumed_at_ns``, ``previous_finished``) and ``segment_messages`` (the message count of each segment
        before this process's, read from its finished summary; None where it cannot be read)."""
        rep = self.recorder.report() if self.recorder is not None else {}
        if self.losses:
            first = None
            if self.recorder is not None and self.recorder.rec.message_counts:
                first = getattr(self.recorder, "first_t_ns", None)
            self.losses[-1]["resumed_at_ns"] = first
        if self._finishing is not None:
            self._finishing.join(120.0)
        if self.losses and self.live_error:
            self.losses[-1]["live_error"] = self.live_error
        counts: list[int | None] = []
        for seg in self.segments[:-1]:
            try:
                counts.append(message_time_range(seg)[2])
            except Exception:  # noqa: BLE001 - unfinished or unreadable: unknown, said so in the summary
                counts.append(None)
        return {**rep, "segments": list(self.segments), "losses": [dict(x) for x in self.losses],
                "segment_messages": counts}

    def stats(self) -> dict:
        return {"_host": {"received": self.received, "errors": [], "error_count": 0}}


def _earlier_loss(segment: Any, following: Any) -> dict:
    """The loss of a recorder death before the last one: ``segment`` ended there, ``following`` went on (both
    finished by the recorder that followed; None times where one cannot be read)."""
    loss = {"segment": str(segment), "next_segment": str(following), "recorded_until_ns": None,
            "resumed_at_ns": None, "previous_finished": False}
    try:
        loss["recorded_until_ns"] = message_time_range(segment)[1]
        loss["previous_finished"] = True
        loss["resumed_at_ns"] = message_time_range(following)[0]
    except Exception as e:  # noqa: BLE001 - reported; `aerodaas recover` can try again
        loss["finish_error"] = f"{type(e).__name__}: {e}"
    return loss

