"""Same-node channels: how an actor hands messages — frames above all — to another actor of the run on the same
machine without paying Ray's per-call costs.

Why (measured, ``docs/benchmarks.md``): one 1280x720 frame hop through Ray on this machine kind costs about
``ray.put`` 1.8 ms + actor call 2.1 ms + ``ray.get`` 0.3 ms + the reply 1.8 ms, so an analytics in its own actor
cost 7.9 ms of framework overhead per frame against 4.3 ms for the same pipeline on dora-rs (one process per node,
shared memory, a persistent channel). A channel does what dora-rs does, between Ray actors that Ray placed, named
and restarts:

* the frame's pixels are copied once into a **shared-memory slot** (POSIX shared memory,
  :class:`multiprocessing.shared_memory.SharedMemory`) owned by the sending actor, which the receiver maps and reads
  in place (a read-only (H, W, 3) uint8 BGR ``ndarray`` over the slot; no copy on the receiving side);
* the message itself (a :class:`~aerodaas.protocol.messages.Delivery`, small) travels on a **persistent, authenticated Unix
  socket** (:mod:`multiprocessing.connection`: HMAC challenge with the run's key both ways), and the outputs bound
  for the sender (detections, navigation) come back on the same socket as soon as the receiver is done — no Ray
  task submission per frame in either direction;
* a camera whose source can render into a buffer (:attr:`aerodaas.plugins.frames.FrameSource.renders_into`, the
  simulator's) makes the frame straight in a slot the outlet lends (:meth:`ChannelOutlet.lend`): that frame is sent
  from there, with no copy at all;
* a slot is reused only once the receiver released the frame: the receiver sends :class:`SlotFree` when its last
  reference to the array is gone (``weakref.finalize``), so an analytics that keeps a frame keeps its slot, exactly
  as an ObjectRef would keep its object. A sender whose slots are all held (a receiver that keeps frames, or an
  analytics scheduler holding many queued tasks) sends the frame's bytes in the message itself instead (one more
  copy, counted as ``inline_frames``): never overwritten, never dropped for want of a slot.

Addresses are Linux abstract Unix sockets named from the run and the receiving actor (:func:`channel_address`):
an actor of another machine (or another network namespace) is simply not found there, and the sender falls back
to Ray (an ObjectRef on the same tier, JPEG across tiers). Every actor of a run serves one (:class:`ChannelServer`);
a restarted actor serves it again under the same address and senders reconnect. Lock-step runs use the same
channels: a delivery of a lock-step cascade (:attr:`~aerodaas.protocol.messages.Delivery.cascade`) is answered when
the receiver's cascade for it is done (never blocking the connection's thread), and the sender's cascade stays
open until that answer and its replies were handed on.

Messages: :class:`ChannelSend` (sender -> receiver), :class:`ChannelDone` and :class:`SlotFree` (receiver ->
sender), in :mod:`.channel_msgs`; a frame's ``data`` in a delivery is a :class:`SlotFrame`. On the socket a frame's
delivery and its answer travel as tuples of built-in values (:mod:`.channel_wire`): the answer's detections
flattened, and the frame's metadata not sent back (the sender puts back the object it sent).
"""
from __future__ import annotations

import hashlib
import socket
from collections import deque
import threading
import time
import weakref
from multiprocessing import connection as mpc
from multiprocessing.shared_memory import SharedMemory
from typing import Any, Callable

import numpy as np

from aerodaas.actors.channel_msgs import ChannelDone, ChannelSend, SlotFrame, SlotFree
from aerodaas.actors.channel_slots import Slot, attach
from aerodaas.actors.channel_wire import decode, decode_done, encode_done, encode_free, encode_send
from aerodaas.protocol.messages import Delivery, FrameMsg, Message, Port

__all__ = ["channel_address", "SlotFrame", "ChannelSend", "ChannelDone", "SlotFree", "ChannelServer",
           "ChannelOutlet"]


def channel_address(run_key: bytes, actor_id: str) -> str:
    """The abstract Unix socket address (Linux) of actor ``host_id``'s channel server in the run whose key is
    ``run_key``: ``\\0aerodaas-`` + 32 hex digits of SHA-256 (fits the 108-byte ``sun_path`` whatever the id)."""
    return "\0aerodaas-" + hashlib.sha256(run_key + actor_id.encode()).hexdigest()[:32]


def _shutdown(conn: Any) -> None:
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


def _freed(freed: deque, wake: threading.Event, name: str, server_thread: int) -> None:
    """A mapped frame was collected: its slot joins ``freed``; the late-frees thread is woken only off the connection's
    own thread (``server_thread``), whose next answer carries it (a thread switch per frame saved)."""
    freed.append(name)
    if threading.get_ident() != server_thread:
        wake.set()


class _SenderSession:
    """One authenticated sender's connection on the receiving side: answers are sent under one lock (a cascade's
    answer comes from another thread), the slots it mapped (``maps``: shared-memory name -> segment), and the slots
    whose frames were collected since the last answer (``freed``, filled by finalizers; ``wake`` tells the
    thread that reports those freed after their delivery was answered, :meth:`late_frees`)."""

    def __init__(self, conn: Any) -> None:
        self.conn = conn
        self.send_lock = threading.Lock()
        self.maps: dict[str, SharedMemory] = {}
        self.freed: deque[str] = deque()
        self.wake = threading.Event()
        self.stop = threading.Event()
        threading.Thread(target=self.late_frees, name="aerodaas-channel-free", daemon=True).start()

    def send(self, obj: tuple) -> None:
        """Send one wire tuple (:mod:`.channel_wire`) to the sender."""
        with self.send_lock:
            try:
                self.conn.send(obj)
            except (OSError, ValueError):  # the sender is gone: nothing to tell it
                pass

    def take_freed(self) -> tuple[str, ...]:
        out = []
        while True:  # three threads may take (this connection's, the late-frees one, a cascade's finisher)
            try:
                out.append(self.freed.popleft())
            except IndexError:
                return tuple(out)

    def late_frees(self) -> None:
        """Frames that outlived their delivery (kept, queued): told when collected."""
        while not self.stop.is_set():
            self.wake.wait(0.5)
            self.wake.clear()
            names = self.take_freed()
            if names:
                self.send(encode_free(SlotFree(names)))

    def close(self) -> None:
        """Stop the late-frees thread, close the connection and unmap the slots no frame holds any more."""
        self.stop.set()
        self.wake.set()
        self.conn.close()
        for shm in self.maps.values():
            try:
                shm.close()
            except BufferError:  # an analytics still holds a frame of it: unmapped when that is collected
                pass


class ChannelServer:
    """The receiving end of every channel into one actor: listens on :func:`channel_address`, authenticates each
    sender with the run's key and serves it on a thread of its own. ``deliver(d) -> replies`` is the actor's
    :meth:`~.dataplane.DataPlane.deliver`; it runs in the connection's thread (as a Ray actor call runs in one of the actor's
    threads); for a delivery of a lock-step cascade it is called as ``deliver(d, answer)``, returns None and calls
    ``answer(replies)`` once the cascade is done (from whichever thread finished it). Raises OSError if the
    address is taken (another live process serves it)."""

    def __init__(self, address: str, key: bytes, deliver: Callable[[Delivery], list],
                 on_error: Callable[[str, BaseException], None] | None = None) -> None:
        self.address, self._key, self._deliver = address, key, deliver
        self._on_error = on_error or (lambda where, e: None)
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self._sock.bind(address)
            self._sock.listen(16)
            self._sock.settimeout(0.25)  # the accept loop looks at _closed this often (close() waits for it)
        except OSError:
            self._sock.close()
            raise
        self._closed = False
        self._conns: set = set()
        self._conns_lock = threading.Lock()
        self.connections = 0
        self.received = 0
        self.failed = 0
        self._acceptor = threading.Thread(target=self._accept_loop, name="aerodaas-channel-accept", daemon=True)
        self._acceptor.start()

    def _accept_loop(self) -> None:
        while not self._closed:
            try:
                s, _ = self._sock.accept()
            except socket.timeout:
                continue
            except OSError:
                if self._closed:
                    return
                time.sleep(0.05)
                continue
            conn = mpc.Connection(s.detach())
            threading.Thread(target=self._serve, args=(conn,), name="aerodaas-channel-in", daemon=True).start()

    def _serve(self, conn: Any) -> None:
        """One sender: authenticate (the run's key, both ways), then hand over each delivery and answer it.

        The connection is known to :meth:`close` before the handshake: the sender's side of the handshake ends one
        message before ours, so a sender may already send while we still authenticate — a close() then must still
        end this connection, or the sender would wait for an answer from a server that stopped."""
        if not self._accept(conn):
            return
        self.connections += 1
        session = _SenderSession(conn)
        maps, freed, wake, send = session.maps, session.freed, session.wake, session.send
        me = threading.get_ident()
        try:
            while True:
                try:
                    item = decode(conn.recv())
                except (EOFError, OSError):
                    return
                if self._closed:  # read from the buffer after close(): the sender counts it failed, so hand nothing on
                    return
                if not isinstance(item, ChannelSend):
                    continue
                self.received += 1
                seq, d = item.seq, item.delivery
                meta = d.msg.meta  # a reply carrying this very object says so instead (channel_wire.SAME_META)
                item = None
                error = None
                replies: list = []
                try:
                    if isinstance(d.msg, FrameMsg) and isinstance(d.msg.data, SlotFrame):
                        t0 = time.time()
                        d.msg.data = self._map(d.msg.data, maps, freed, wake, me)
                        d.msg.trace["get_ms"] = (time.time() - t0) * 1e3
                    elif isinstance(d.msg, FrameMsg) and isinstance(d.msg.data, np.ndarray):
                        d.msg.data.flags.writeable = False  # sent inline: shared by every reader here too
                        d.msg.trace["get_ms"] = 0.0
                    if d.cascade:  # answered when the cascade it starts here is done; this thread reads on
                        self._deliver(d, lambda r, seq=seq, meta=meta: send(
                            encode_done(ChannelDone(seq, r, None, session.take_freed()), meta)))
                        d = None
                        if freed:  # freed here but answered later: the late-frees thread tells them
                            wake.set()
                        continue
                    else:
                        replies = self._deliver(d)
                except Exception as e:  # noqa: BLE001 - answered as failed; the actor goes on
                    self.failed += 1
                    error = f"{type(e).__name__}: {e}"
                    self._on_error("channel", e)
                d = None  # this thread's last reference to the frame: usually frees its slot right here
                send(encode_done(ChannelDone(seq, replies, error, session.take_freed()), meta))
                meta = None
        finally:
            with self._conns_lock:
                self._conns.discard(conn)
            session.close()

    def _accept(self, conn: Any) -> bool:
        """Register ``conn`` (known to :meth:`close` before the handshake) and authenticate it with the run's key,
        both ways. False (closed) when the server is closed or the peer is not one of the run's actors."""
        with self._conns_lock:
            if self._closed:
                conn.close()
                return False
            self._conns.add(conn)
        try:
            mpc.deliver_challenge(conn, self._key)
            mpc.answer_challenge(conn, self._key)
        except Exception:  # noqa: BLE001 - not one of the run's actors (or closed under us): drop it
            with self._conns_lock:
                self._conns.discard(conn)
            conn.close()
            return False
        return True

    @staticmethod
    def _map(sf: SlotFrame, maps: dict[str, SharedMemory], freed: deque, wake: threading.Event,
             server_thread: int) -> np.ndarray:
        """The read-only array over slot ``sf`` (mapped once per slot); when the last reference to it goes, its
        name joins ``freed`` (never a send from a finalizer: it may run inside another send of this thread)."""
        shm = maps.get(sf.name)
        if shm is None:
            shm = maps[sf.name] = attach(sf.name)
        arr = np.ndarray(sf.shape, np.dtype(sf.dtype), buffer=shm.buf)
        arr.flags.writeable = False
        weakref.finalize(arr, _freed, freed, wake, sf.name, server_thread)
        return arr

    def close(self) -> None:
        """Stop serving: the address is released and every sender's connection is closed (they count what they had
        in flight as failed)."""
        with self._conns_lock:
            self._closed = True
            conns = list(self._conns)
        for conn in conns:
            _shutdown(conn)
        if self._acceptor is not threading.current_thread():
            self._acceptor.join(2.0)  # it leaves accept() within its timeout; then the address is free at once
        self._sock.close()


class ChannelOutlet:
    """The sending end of an edge to component ``cid`` of a peer actor on the same machine, over that peer's
    channel (the same interface as :class:`~.remote_outlet.RemoteOutlet`: :meth:`send`, :meth:`stats`).

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
        self.reconnects = 0
        self.late_frees = 0  # SlotFree messages: frames the receiver released after answering their delivery
        self.closed = False
        self.connect()

    # ------------------------------------------------------------------ connection
    def connect(self) -> None:
        """Open the channel (authenticating with the run's key). Raises OSError if nobody serves the address,
        AuthenticationError if the server is not one of this run's actors."""
        conn = mpc.Client(self.address, family="AF_UNIX", authkey=self._key)
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
                    _, tok, meta = self._in_flight.pop(item.seq, (None, None, None))
                    if item.error is not None:
                        self.failed += 1
                    self._free(item.freed)
                try:
                    if item.replies:
                        item = ChannelDone(item.seq, decode_done(item.replies, meta), item.error, item.freed)
                        if tok is not None:  # the replies join the cascade that waited for this answer
                            for d in item.replies:
                                d.msg.tok = tok
                        try:
                            self.on_reply(item.replies)
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
        while self._unlent:  # lent frames collected since: their slots are this outlet's to write again
            name = self._unlent.popleft()
            s = self._slots.get(name)
            if s is not None:
                s.lent = False
            for addr in [a for a, n in self._lent.items() if n == name]:
                del self._lent[addr]
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
            slot = self._slot(nbytes)
            if slot is None:
                return None
            slot.free, slot.lent = True, True  # no receiver holds it yet; a frame here does
            arr = np.ndarray(shape, dtype, buffer=slot.shm.buf)
            self._lent[arr.ctypes.data] = slot.shm.name
        weakref.finalize(arr, self._unlent.append, slot.shm.name)
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
            except (OSError, ValueError):
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
                    "inline_frames": self.inline_frames, "in_place": self.in_place, "reconnects": self.reconnects,
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
            _shutdown(conn)
            try:
                conn.close()
            except OSError:
                pass
        for s in slots:
            s.drop()
