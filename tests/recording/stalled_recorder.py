"""A stand-in for the run's recorder actor that takes no batch until released (as a SIGSTOPped one), and the part of
a data plane a :class:`~aerodaas.actors.recording.remote_recorder.RemoteRecorder` needs, shared by the recorder tests."""
from __future__ import annotations

import threading


class StalledRecorder:
    """A recorder actor that takes no batch until :meth:`release` (as a SIGSTOPped one): ``record`` waits."""

    def __init__(self) -> None:
        self.gate = threading.Event()
        self.frames = 0

    def ledger_of(self, producer: str):
        from aerodaas.protocol.messages import ProducerLedger

        return ProducerLedger(producer, {}, incarnation=1)

    def record(self, batch: list, ledger=None) -> int:
        self.gate.wait(120)
        self.frames += sum(1 for it in batch if it.topic.endswith("/camera/cam"))
        return len(batch)

    def release(self) -> None:
        self.gate.set()

    def recorded_frames(self) -> int:
        return self.frames


class StalledPlane:
    """What :class:`RemoteRecorder` needs of its actor's data plane: its id and the recorder actor's handle."""

    actor_id = "drone-test"
    copies = None

    def __init__(self, recorder) -> None:
        self.recorder = recorder

    def peer(self, name: str):
        return self.recorder
