"""The run's memory of its drones: the newest checkpoint of each robot, as the recorder actor keeps it for a drone
actor that Ray restarts (:meth:`aerodaas.actors.recording.actor.RecorderActor.checkpoint`), with the waypoint queue
it goes with (:class:`~aerodaas.protocol.messages.SealedCheckpoint`: the queue travels apart, only when it changed
otherwise than by flying). Everything stays sealed: nothing here unpickles a checkpoint."""
from __future__ import annotations

import threading

from aerodaas.protocol.messages import SealedCheckpoint

__all__ = ["CheckpointStore"]


class CheckpointStore:
    """Each robot's newest checkpoint and the sealed queues it may go with. Thread-safe (one lock): the recorder
    actor's calls run on its threads."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._cp: dict[str, SealedCheckpoint] = {}
        #: robot -> queue id -> sealed waypoint queue: the one its kept checkpoint goes with, and any newer
        self._queues: dict[str, dict[int, bytes]] = {}

    def keep(self, robot_id: str, sealed: SealedCheckpoint) -> bool:
        """Keep ``sealed`` as the newest checkpoint of ``robot_id`` (an older one, by its sequence number, is
        ignored), with the waypoint queue it goes with (carried by it or by an earlier one; a queue that no kept
        checkpoint can go with any more is dropped). Returns False when it goes with a queue not kept here (the
        recorder restarted since that queue was sent, or the queue is still on its way): the drone actor then
        sends its queue again with its next checkpoint."""
        with self._lock:
            queues = self._queues.setdefault(robot_id, {})
            if sealed.queue_blob is not None:
                queues[sealed.queue_id] = sealed.queue_blob
                sealed = sealed.with_queue(sealed.queue_id, None)  # kept once, beside the checkpoints
            old = self._cp.get(robot_id)
            if old is None or sealed.seq >= old.seq:
                if sealed.queue_id and sealed.queue_id not in queues:
                    return False
                self._cp[robot_id] = old = sealed
            for qid in [q for q in queues if old is not None and q < old.queue_id]:
                del queues[qid]
        return True

    def last(self, robot_id: str) -> SealedCheckpoint | None:
        """The newest checkpoint of ``robot_id``, sealed (``.open()`` it) with the queue it goes with, or None."""
        with self._lock:
            cp = self._cp.get(robot_id)
            if cp is None or not cp.queue_id:
                return cp
            return cp.with_queue(cp.queue_id, self._queues[robot_id][cp.queue_id])
