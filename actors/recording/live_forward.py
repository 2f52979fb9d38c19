"""A node's recorder forwards what it wrote to the driver's recorder, whose live view then shows every node's
channels (one recorder per node, :mod:`aerodaas.runtime.node_recorders`; only with a live view).

:class:`LiveForwarder` is a sink of the node recorder's :class:`~aerodaas.recording.writer.McapRecorder`
(:meth:`~aerodaas.recording.writer.McapRecorder.add_sink`): it keeps each message as written (topic, schema,
encoding, log time, bytes: a :class:`~aerodaas.recording.writer.RecordedMessage`) and a background thread sends
them in batches, every ``period_s`` seconds, to the driver's recorder actor
(:meth:`~aerodaas.actors.recording.actor.RecorderActor.publish_live`), which hands them to its live server as its
own writer does. The recording never waits for it: beyond ``max_pending_bytes`` waiting, messages are not forwarded
(counted in ``dropped``; the node's file has them all).
"""
from __future__ import annotations

import threading
from typing import Any

from aerodaas.recording.writer import RecordedMessage

__all__ = ["LiveForwarder"]


class LiveForwarder:
    """Forwards ``RecordedMessage`` s to ``target`` (the driver's recorder actor handle), see the module docstring.
    ``period_s``: seconds between batches; ``max_pending_bytes``: bytes of message data waiting at most."""

    def __init__(self, target: Any, period_s: float = 0.1, max_pending_bytes: int = 64 << 20) -> None:
        self.target, self.period_s, self.max_pending_bytes = target, period_s, max_pending_bytes
        self._buf: list[RecordedMessage] = []
        self._bytes = 0
        self._lock = threading.Lock()
        self._refs: list = []
        self.sent = 0
        self.dropped = 0
        self.errors: list[str] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="aerodaas-live-forward", daemon=True)
        self._thread.start()

    def __call__(self, msg: RecordedMessage) -> None:
        """The sink: keep ``msg`` for the next batch (returns at once)."""
        with self._lock:
            if self._bytes + len(msg.data) > self.max_pending_bytes:
                self.dropped += 1
                return
            self._buf.append(msg)
            self._bytes += len(msg.data)

    def _send(self) -> None:
        import ray  # lazy: heavy ray

        with self._lock:
            batch, self._buf, self._bytes = self._buf, [], 0
        if batch:
            try:
                self._refs.append(self.target.publish_live.remote(batch))
                self.sent += len(batch)
            except Exception as e:  # noqa: BLE001 - the live view only: never stops the recording
                self.errors.append(f"{type(e).__name__}: {e}")
        done, self._refs = ray.wait(self._refs, num_returns=len(self._refs), timeout=0)
        for ref in done:
            try:
                ray.get(ref)
            except Exception as e:  # noqa: BLE001
                self.errors.append(f"{type(e).__name__}: {e}")

    def _loop(self) -> None:
        while not self._stop.wait(self.period_s):
            self._send()

    def close(self, timeout_s: float = 30.0) -> None:
        """Send what is left and wait (at most ``timeout_s``) for the driver's recorder to have published it."""
        import ray  # lazy: heavy ray

        self._stop.set()
        self._thread.join(timeout_s)
        self._send()
        try:
            ray.get(self._refs, timeout=timeout_s)
        except Exception as e:  # noqa: BLE001
            self.errors.append(f"{type(e).__name__}: {e}")
        self._refs = []
