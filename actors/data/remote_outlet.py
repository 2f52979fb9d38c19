"""The sending side of a route to a component of another actor over Ray: a bounded number of deliveries in
flight, the frame put once into the object store on one tier and JPEG-encoded across tiers, replies handed back
to the sending data plane (see :mod:`aerodaas.actors.data.plane`; the same-node alternative is :mod:`aerodaas.actors.data.channel`)."""
from __future__ import annotations

import threading
import time
from typing import Any, Callable

import ray

from aerodaas.actors.data.cascade import Cascade
from aerodaas.actors.data.frames import FrameCopies, encode_frame
from aerodaas.protocol.messages import Delivery, EncodedFrame, FrameMsg, Message, Port

__all__ = ["RemoteOutlet"]


class RemoteOutlet:
    """The producer's end of an edge to a component on another actor (a Ray actor call to ``DataPlane.deliver``).

    Allows ``buffer`` calls in flight; when the consumer is still busy with them a new item is dropped and
    counted. Frames are JPEG-encoded when the edge crosses tiers (``jpeg``), else sent as an ObjectRef."""

    transport = "ray"

    def __init__(self, handle: Any, cid: str, port: Port, buffer: int, jpeg: bool,
                 copies: FrameCopies | None = None, reply_to: str | None = None,
                 on_reply: Callable[[list], None] | None = None, hold_s: float = 60.0,
                 retry_s: float = 0.2) -> None:
        self.handle, self.cid, self.port = handle, cid, port
        #: this actor's id: the consumer returns the outputs bound for this actor in the call's reply (one actor call
        #: per round trip instead of two); ``on_reply`` hands them to the local components
        self.reply_to, self.on_reply = reply_to, on_reply
        self.copies = copies if copies is not None else FrameCopies()
        self.buffer = max(1, int(buffer))
        self.jpeg = jpeg
        self.in_flight: list = []
        self.sent = 0
        self.dropped = 0
        self.failed = 0  # calls that ended in an error (the consumer's actor died or restarted meanwhile)
        #: lock-step: a call refused because the consumer's actor is restarting is sent again every ``retry_s``
        #: for up to ``hold_s`` seconds (``held`` counts the retries), its cascade keeping the clock still meanwhile
        self.hold_s, self.retry_s = max(0.0, float(hold_s)), retry_s
        self.held = 0
        #: called with each item dropped because ``buffer`` calls are in flight (load shed, not lost: the recording's
        #: accounting counts it as taken without output, :mod:`aerodaas.recording.accounting`)
        self.on_shed: Callable[[Message], None] | None = None
        self.lost = False  # a lock-step call's hold ran out with the consumer still restarting (see lost_consumers)
        self._retried: set = set()  # refs of calls that were sent again: not counted as failed when reaped
        self._retrying = 0  # retries waiting for their timer
        #: reentrant: a call's future that is already done runs its callback (which takes the lock) at once
        self._lock = threading.RLock()

    def _reap(self) -> None:
        """Forget finished calls; count those that failed (frames in flight when the consumer died)."""
        done, self.in_flight = ray.wait(self.in_flight, num_returns=len(self.in_flight), timeout=0)
        for ref in done:
            try:
                ray.get(ref, timeout=0)
            except Exception:  # noqa: BLE001 - ActorDiedError, ActorUnavailableError, the consumer's own error
                if ref in self._retried:
                    self._retried.discard(ref)
                else:
                    self.failed += 1

    def send(self, msg: Message) -> Any:
        """Send one message; returns the call's ObjectRef or None if dropped. A frame is put into the object store
        (or JPEG-encoded, across tiers) once per message, however many consumers of other actors it has (the
        message keeps the ref). A message of a lock-step :class:`Cascade` (``msg.tok``) is never dropped: the
        cascade stays open until the call returned (the receiver's cascade for it is done) and its replies were
        handed on."""
        tok = msg.tok
        with self._lock:
            if self.in_flight:
                self._reap()
            if tok is None and len(self.in_flight) >= self.buffer:
                self.dropped += 1
                if self.on_shed is not None:
                    self.on_shed(msg)
                return None
            if isinstance(msg, FrameMsg):
                t0 = time.time()
                if self.jpeg:
                    if msg.jpeg is None:
                        msg.jpeg = EncodedFrame(encode_frame(msg.data))
                        self.copies.count("tier_jpeg_encoded")
                    wire = msg.to_wire(msg.jpeg)
                else:
                    if msg.ref is None:
                        msg.ref = ray.put(msg.data)
                        self.copies.count("object_store_put")
                    wire = msg.to_wire(msg.ref)
                # where the time of a hop goes (see SchedulerComponent's latency records): put/encode, then the call
                wire.trace.update(put_ms=(time.time() - t0) * 1e3, sent_wall=time.time())
            else:
                wire = msg.to_wire()
            d = Delivery(self.cid, self.port, wire, cascade=tok is not None, reply_to=self.reply_to)
            self.sent += 1
            if tok is not None:
                tok.add()
            return self._submit(d, tok, time.monotonic() + self.hold_s)

    def _submit(self, d: Delivery, tok: Cascade | None, hold_until: float) -> Any:
        """Caller holds ``_lock``: one ``deliver`` call; its reply handled by :meth:`_replied`."""
        ref = self.handle.deliver.remote(d)
        self.in_flight.append(ref)
        if self.on_reply is not None or tok is not None:
            ref.future().add_done_callback(lambda fut: self._replied(fut, tok, d, ref, hold_until))
        return ref

    def _resubmit(self, d: Delivery, tok: Cascade, hold_until: float) -> None:
        with self._lock:
            self._retrying -= 1
            self._submit(d, tok, hold_until)

    def busy(self) -> bool:
        """True while a call is in flight (sent, its reply not yet handed on)."""
        with self._lock:
            if self.in_flight:
                self._reap()
            return bool(self.in_flight) or self._retrying > 0

    def _replied(self, fut: Any, tok: Cascade | None, d: Delivery, ref: Any, hold_until: float) -> None:
        """The consumer's reply (Ray's callback thread: hand over, never block it); then the cascade's hold on the
        call is released (the replies joined it first). A lock-step call refused because the consumer's actor is
        restarting (``ActorUnavailableError``) is sent again after ``retry_s`` while its ``hold_s`` lasts, the
        cascade still held by the retry."""
        try:
            try:
                out = fut.result()
            except ray.exceptions.ActorUnavailableError:
                out = None
                if tok is not None and time.monotonic() >= hold_until:
                    self.lost = True
                elif tok is not None:
                    with self._lock:
                        self._retried.add(ref)
                        self.held += 1
                        self._retrying += 1
                    timer = threading.Timer(self.retry_s, self._resubmit, (d, tok, hold_until))
                    timer.daemon = True
                    timer.start()
                    tok = None  # the retry holds the cascade now
            except ray.exceptions.ActorDiedError:  # gone for good (Ray restarts it no more): counted failed when reaped
                out = None
                if tok is not None:
                    self.lost = True
            except Exception:  # noqa: BLE001 - counted as failed when reaped
                out = None
            else:
                self.lost = False  # answered: the consumer is back
            if out and self.on_reply is not None:
                if tok is not None:
                    for item in out:
                        item.msg.tok = tok
                self.on_reply(out)
        finally:
            if tok is not None:
                tok.done()

    def stats(self) -> dict:
        with self._lock:
            if self.in_flight:
                self._reap()
        return {"port": self.port.wire(), "to": self.cid, "transport": self.transport, "sent": self.sent,
                "dropped": self.dropped, "failed": self.failed, "held": self.held, "lost": self.lost}
