"""The sending end of a same-node channel (:mod:`aerodaas.actors.data.channel` explains the channel): one outlet per
edge from a component of this actor to a component of a peer actor on the same machine, with its shared-memory
slots (copied into, or lent for a frame to be made in) and its deliveries in flight."""
from __future__ import annotations

import socket
import threading
import time
import weakref
from collections import deque
from typing import Any, Callable

import numpy as np

from aerodaas.actors.data.channel_conn import client
from aerodaas.actors.data.channel_msgs import ChannelDone, ChannelSend, SlotFrame, SlotFree
from aerodaas.actors.data.channel_slots import Slot, release_lent
from aerodaas.actors.data.channel_wire import decode, decode_done, encode_send
from aerodaas.protocol.messages import Delivery, FrameMsg, Message, Port

__all__ = ["ChannelOutlet", "shutdown_connection"]


def shutdown_connection(conn: Any) -> None:
    """Shut connection ``conn``'s socket down through a duplicate of its descriptor: wakes a thread blocked in its
    ``recv`` (with EOF) before the connection is closed."""
    try:
        dup = socket.fromfd(conn.fileno(), socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            dup.shutdown(socket.SHUT_RDWR)
        finally:
            dup.close()
    except (OSError, ValueError):
        pass


class ChannelOutlet:
    """The sending end of an edge to component ``cid`` of a peer actor on the same machine, over that peer's
    channel (the same interface as :class:`~aerodaas.actors.data.remote_outlet.RemoteOutlet`: :meth:`send`, :meth:`stats`).

    At most ``buffer`` deliveries are in flight (sent, not yet answered); a new one beyond that is dropped and
    counted, as a busy consumer's mailbox would. Frames go through at most ``max_slots`` shared-memory slots of
    this outlet; replies are handed to ``on_reply`` (this actor's components) from the outlet's reader thread. If
    the peer dies, the deliveries in flight are counted as ``failed`` and the outlet reconnects (at most every
    ``retry_s`` seconds) once the peer's restarted actor serves its address again; meanwhile sends are dropped and
    counted as failed — except a lock-step one (its cascade holds the simulated clock): it waits up to ``hold_s``
    seconds for the restarted peer (counted in ``held``), so that simulated time does not run on without the
    consumer while Ray restarts it; if the peer is not back by then, the outlet stops waiting and reports its
    consumer ``lost`` until it reconnects. :meth:`connect` raises OSError when nobody serves the address (another
    machine: use Ray)."""

    transport = "channel"

    def __init__(self, address: str, key: bytes, cid: str, port: Port, buffer: int, reply_to: str | None,
                 on_reply: Callable[[list], None], copies: Any = None, max_slots: int | None = None,
                 retry_s: float = 0.5, hold_s: float = 60.0) -> None:
        self.address, self._key, self.cid, self.port = address, key, cid, port
        self.buffer = max(1, int(buffer))
        self.max_slots = max_slots or min(16, self.buffer + 3)
        self.reply_to, self.on_reply, self.copies = reply_to, on_reply, copies
        self.retry_s = retry_s
        self.hold_s = max(0.0, float(hold_s))
        self.held = 0  # lock-step sends that waited for the peer's restart
        #: called with each item dropped because ``buffer`` deliveries are in flight (see RemoteOutlet.on_shed)
        self.on_shed: Callable[[Message], None] | None = None
        self.lost = False  # a lock-step send waited hold_s in vain: later ones fail at once until reconnected
        self._lock = threading.Lock()
        self._slots: dict[str, Slot] = {}
        #: lent frames (:meth:`lend`) by the address of their first pixel -> their slot's name
        self._lent: dict[int, str] = {}
        #: slots whose lent frame was collected here (filled by finalizers, taken under the lock)
        self._unlent: deque[str] = deque()
        #: seq -> (slot name or None: no frame, the lock-step cascade waiting for the answer or None, the FrameMeta
        #: sent: the answer's replies refer to it instead of sending it back, channel_wire.SAME_META)
        self._in_flight: dict[int, tuple[str | None, Any, Any]] = {}
        self._seq = 0
        self._conn: Any = None
        self._next_try = 0.0
        self.sent = self.dropped = self.failed = 0
        self.inline_frames = 0  # frames sent in the message itself: the receiver still held every slot
        self.in_place = 0  # frames made in a lent slot and sent from there, not copied
        self.lend_refused = 0  # lend() calls answered None (slots held): those frames were made as usual
        self.reconnects = 0
        self.late_frees = 0  # SlotFree messages: frames the receiver released after answering their delivery
        self.closed = False
        self.connect()

    # ------------------------------------------------------------------ connection
    def connect(self) -> None:
        """Open the channel (authenticating with the run's key). Raises OSError if nobody serves the address,
        AuthenticationError if the server is not one of this run's actors."""
        conn = client(self.address, self._key)
        self._conn = conn
        threading.Thread(target=self._read_loop, args=(conn,), name="aerodaas-channel-out", daemon=True).start()

    def _read_loop(self, conn: Any) -> None:
        while True:
            try:
                item = decode(conn.recv())
            except Exception:  # noqa: BLE001 - EOF, reset, or closed under us by close(): the channel is over
                break
            if isinstance(item, ChannelDone):
                with self._lock:
                    known = item.seq in self._in_flight
                    _, tok, meta = self._in_flight.pop(item.seq, (None, None, None))
                    if item.error is not None:
                        self.failed += 1
                    self._free(item.freed)
                try:
                    if item.replies and known:  # an answer to a delivery no longer in flight (closed): dropped
                        try:
                            replies = decode_done(item.replies, meta)
                        except Exception:  # noqa: BLE001 - an answer that does not decode: failed, the channel goes on
                            with self._lock:
                                self.failed += 1
                            continue
                        if tok is not None:  # the replies join the cascade that waited for this answer
                            for d in replies:
                                d.msg.tok = tok
                        try:
                            self.on_reply(replies)
                        except Exception:  # noqa: BLE001 - the receiving component counts its own errors
                            pass
                finally:
                    if tok is not None:
                        tok.done()
            elif isinstance(item, SlotFree):
                with self._lock:
                    self.late_frees += 1
                    self._free(item.names)
        lost: list = []
        with self._lock:  # the peer died (or closed): what was in flight is lost; its mappings went with it
            if self._conn is conn:
                self._conn = None
                self.failed += len(self._in_flight)
                lost = self._take_in_flight()
                for s in self._slots.values():
                    s.free = True
                self._next_try = time.monotonic() + self.retry_s
        for tok in lost:  # a lost delivery no longer holds its lock-step cascade open
            tok.done()
        try:
            conn.close()
        except OSError:
            pass

    def _take_in_flight(self) -> list:
        """Caller holds ``_lock``: forget every delivery in flight; returns the cascades they held open."""
        toks = [tok for _, tok, _ in self._in_flight.values() if tok is not None]
        self._in_flight.clear()
        return toks

    def _free(self, names: tuple[str, ...]) -> None:
        """Caller holds ``_lock``: slots ``names`` may be written again."""
        for n in names:
            slot = self._slots.get(n)
            if slot is not None:
                slot.free = True

    def _ensure(self) -> bool:
        """Caller holds ``_lock``. True when connected (reconnecting when due)."""
        if self._conn is not None:
            return True
        if self.closed or time.monotonic() < self._next_try:
            return False
        try:
            self.connect()
            self.reconnects += 1
            self.lost = False
            return True
        except Exception:  # noqa: BLE001 - the peer is restarting: try again later
            self._next_try = time.monotonic() + self.retry_s
            return False

    def _await_peer(self) -> None:
        """A lock-step send found the peer down: wait (at most ``hold_s`` seconds, retrying every ``retry_s``) until
        its restarted actor serves the channel again. The cascade of the message waiting keeps the clock still."""
        deadline = time.monotonic() + self.hold_s
        with self._lock:
            if self._conn is not None or self.closed or self.lost:
                return
            self.held += 1
        while True:
            with self._lock:
                if self.closed or self._conn is not None:
                    return
                self._next_try = 0.0
                if self._ensure():
                    return
                if time.monotonic() >= deadline:
                    self.lost = True
                    return
            time.sleep(min(self.retry_s, max(0.0, deadline - time.monotonic())))

    # ------------------------------------------------------------------ sending
    def _slot(self, nbytes: int) -> Slot | None:
        """Caller holds ``_lock``. A free slot of at least ``nbytes`` bytes (a new one while fewer than
        ``max_slots`` exist; a too-small free one is replaced), or None when the receiver (or lent frames here)
        hold them all."""
        self._take_unlent()
        for s in self._slots.values():
            if s.free and not s.lent and s.size >= nbytes:
                s.free = False
                return s
        if len(self._slots) >= self.max_slots:
            small = next((s for s in self._slots.values() if s.free and not s.lent), None)
            if small is None:
                return None
            del self._slots[small.shm.name]
            small.drop()
        s = Slot(nbytes)
        self._slots[s.shm.name] = s
        s.free = False
        return s

    def _take_unlent(self) -> None:
        """Caller holds ``_lock``. The slots of lent frames collected since (:func:`release_lent`) are this
        outlet's to write again."""
        while self._unlent:
            name = self._unlent.popleft()
            s = self._slots.get(name)
            if s is not None:
                s.lent = False
            for addr in [a for a, n in self._lent.items() if n == name]:
                del self._lent[addr]

    def lend(self, shape: tuple[int, ...], dtype: Any = np.uint8) -> np.ndarray | None:
        """A writable array of ``shape`` and ``dtype`` over one of this outlet's slots, for a frame to be made in
        (a camera's render, :attr:`aerodaas.plugins.frames.FrameSource.renders_into`): when that array is then
        sent, it is not copied (counted in ``in_place``). The slot is written again only once this process no
        longer references the array (a finalizer tells) and the receiver let go of the frame. None when the channel
        is down or every slot is held."""
        nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
        with self._lock:
            if self.closed or self._conn is None:
                return None
            self._take_unlent()
            if sum(s.lent for s in self._slots.values()) >= self.max_slots - 2:
                # frames made here are still referenced (a recorder catching up, the camera's latest frame): the
                # last two slots stay for copies, or every frame would travel in its message
                self.lend_refused += 1
                return None
            slot = self._slot(nbytes)
            if slot is None:
                self.lend_refused += 1
                return None
            slot.free, slot.lent = True, True  # no receiver holds it yet; a frame here does
            arr = np.ndarray(shape, dtype, buffer=slot.shm.buf)
            self._lent[arr.ctypes.data] = slot.shm.name
        weakref.finalize(arr, release_lent, self._unlent, slot)
        return arr

    def _lent_slot(self, frame: np.ndarray) -> Slot | None:
        """Caller holds ``_lock``. The slot ``frame`` was made in (:meth:`lend`), when it is one of this outlet's
        lent frames as lent (C-contiguous, from its first pixel), else None."""
        name = self._lent.get(frame.ctypes.data)
        s = self._slots.get(name) if name is not None else None
        if s is None or not s.lent or not s.free or frame.nbytes > s.size or not frame.flags.c_contiguous:
            return None
        return s

    def send(self, msg: Message) -> int | None:
        """Send one message; returns its delivery number, or None when dropped (too many in flight, or the peer is
        down: counted in ``dropped`` / ``failed``). A message of a lock-step cascade (``msg.tok``) is never dropped
        for being over ``buffer`` (the clock bounds what is in flight); the cascade stays open until the receiver
        answered that its own cascade for it is done, and the replies in that answer were handed on."""
        tok = msg.tok
        if tok is not None and self._conn is None:
            self._await_peer()
        with self._lock:
            if not self._ensure():
                self.failed += 1
                return None
            if tok is None and len(self._in_flight) >= self.buffer:
                self.dropped += 1
                if self.on_shed is not None:
                    self.on_shed(msg)
                return None
            slot_name = None
            t0 = time.time()
            if isinstance(msg, FrameMsg):
                frame = msg.data
                slot = self._lent_slot(frame)
                if slot is not None:  # made in this very slot (lend): nothing to copy
                    slot.free = False
                    self.in_place += 1
                    copied = "channel_in_place"
                else:
                    slot = self._slot(frame.nbytes)
                    copied = "channel_copy"
                if slot is None:  # every slot held by the receiver: the pixels travel in the message
                    self.inline_frames += 1
                    wire = msg.to_wire()
                else:
                    if copied == "channel_copy":
                        np.copyto(np.ndarray(frame.shape, frame.dtype, buffer=slot.shm.buf), frame)
                    slot_name = slot.shm.name
                    wire = msg.to_wire(SlotFrame(slot_name, tuple(frame.shape), frame.dtype.str))
                if self.copies is not None:
                    self.copies.count(copied)
                wire.trace.update(put_ms=(time.time() - t0) * 1e3)
            else:
                wire = msg.to_wire()
            wire.trace["sent_wall"] = time.time()
            self._seq += 1
            seq = self._seq
            try:
                d = Delivery(self.cid, self.port, wire, cascade=tok is not None, reply_to=self.reply_to)
                self._conn.send(encode_send(ChannelSend(seq, d)))
            except Exception:  # noqa: BLE001 - the peer is gone, or the message does not pickle: failed
                if slot_name is not None:
                    self._slots[slot_name].free = True
                self.failed += 1
                return None
            if tok is not None:
                tok.add()  # the reader thread cannot see the answer before this lock is released
            self._in_flight[seq] = (slot_name, tok, wire.meta)
            self.sent += 1
            return seq

    @property
    def connected(self) -> bool:
        """True while the channel to the peer is open (False from the peer's death until the next reconnect)."""
        with self._lock:
            return self._conn is not None

    def busy(self) -> bool:
        """True while a delivery is in flight (sent, not yet answered by the peer)."""
        with self._lock:
            return bool(self._in_flight)

    def stats(self) -> dict:
        with self._lock:
            return {"port": self.port.wire(), "to": self.cid, "transport": self.transport, "sent": self.sent,
                    "dropped": self.dropped, "failed": self.failed, "slots": len(self._slots),
                    "inline_frames": self.inline_frames, "in_place": self.in_place, "lend_refused": self.lend_refused,
                    "reconnects": self.reconnects,
                    "held": self.held,
                    "late_frees": self.late_frees,
                    "lost": self.lost}

    def close(self) -> None:
        """Close the channel and unlink this outlet's slots (a receiver still holding a frame keeps its mapping)."""
        with self._lock:
            self.closed = True
            conn, self._conn = self._conn, None
            slots, self._slots = list(self._slots.values()), {}
            lost = self._take_in_flight()
        for tok in lost:
            tok.done()
        if conn is not None:
            shutdown_connection(conn)
            try:
                conn.close()
            except OSError:
                pass
        for s in slots:
            s.drop()
