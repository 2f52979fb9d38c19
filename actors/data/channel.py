"""Same-node channels: how an actor hands messages — frames above all — to another actor of the run on the same
machine without paying Ray's per-call costs.

Why (measured, ``docs/results/overhead.md``): one 1280x720 frame hop through Ray on this machine kind costs about
``ray.put`` 1.8 ms + actor call 2.1 ms + ``ray.get`` 0.3 ms + the reply 1.8 ms, so an analytics in its own actor
cost 7.9 ms of framework overhead per frame against 4.3 ms for the same pipeline on dora-rs (one process per node,
shared memory, a persistent channel). A channel does what dora-rs does, between Ray actors that Ray placed, named
and restarts:

* the frame's pixels are copied once into a **shared-memory slot** (POSIX shared memory,
  :class:`~aerodaas.actors.data.channel_slots.Segment`) owned by the sending actor, which the receiver maps and reads
  in place (a read-only (H, W, 3) uint8 BGR ``ndarray`` over the slot; no copy on the receiving side);
* the message itself (a :class:`~aerodaas.protocol.messages.Delivery`, small) travels on a **persistent, authenticated Unix
  socket** (:mod:`multiprocessing.connection`: HMAC challenge with the run's key both ways), and the outputs bound
  for the sender (detections, navigation) come back on the same socket as soon as the receiver is done — no Ray
  task submission per frame in either direction;
* a camera whose source can render into a buffer (:attr:`aerodaas.plugins.frames.FrameSource.renders_into`, the
  simulator's) makes the frame straight in a slot the outlet lends (:meth:`aerodaas.actors.data.channel_outlet.ChannelOutlet.lend`):
  that frame is sent from there, with no copy at all;
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

The receiving end is here (:class:`ChannelServer`), the sending end in :mod:`aerodaas.actors.data.channel_outlet`. Messages:
:class:`ChannelSend` (sender -> receiver), :class:`ChannelDone` and :class:`SlotFree` (receiver ->
sender), in :mod:`aerodaas.actors.data.channel_msgs`; a frame's ``data`` in a delivery is a :class:`SlotFrame`. On the socket a frame's
delivery and its answer travel as tuples of built-in values (:mod:`aerodaas.actors.data.channel_wire`): the answer's detections
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
from typing import Any, Callable

import numpy as np

from aerodaas.actors.data.channel_conn import BufferedConnection
from aerodaas.actors.data.channel_msgs import ChannelDone, ChannelSend, SlotFrame, SlotFree
from aerodaas.actors.data.channel_outlet import shutdown_connection
from aerodaas.actors.data.channel_slots import Mapped, attach
from aerodaas.actors.data.channel_wire import decode, encode_done, encode_free
from aerodaas.protocol.messages import Delivery, FrameMsg

__all__ = ["channel_address", "ChannelServer"]


def channel_address(run_key: bytes, actor_id: str) -> str:
    """The abstract Unix socket address (Linux) of actor ``host_id``'s channel server in the run whose key is
    ``run_key``: ``\\0aerodaas-`` + 32 hex digits of SHA-256 (fits the 108-byte ``sun_path`` whatever the id)."""
    return "\0aerodaas-" + hashlib.sha256(run_key + actor_id.encode()).hexdigest()[:32]


def _freed(freed: deque, wake: threading.Event, name: str, server_thread: int, shm: Mapped) -> None:
    """A mapped frame was collected: its slot joins ``freed``; the late-frees thread is woken only off the connection's
    own thread (``server_thread``), whose next answer carries it (a thread switch per frame saved). ``shm``: the
    frame's mapping, held by this finalizer so that it outlives every frame read from it (unmapped when the last
    reference goes, even after the connection ended)."""
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
        self.maps: dict[str, Mapped] = {}
        self.freed: deque[str] = deque()
        self.wake = threading.Event()
        self.stop = threading.Event()
        threading.Thread(target=self.late_frees, name="aerodaas-channel-free", daemon=True).start()

    def send(self, obj: tuple) -> None:
        """Send one wire tuple (:mod:`aerodaas.actors.data.channel_wire`) to the sender."""
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
        """Stop the late-frees thread, close the connection and let go of the mappings: one no frame holds is
        unmapped at once, one an analytics still holds a frame of when that frame is collected (its finalizer holds
        the mapping: numpy holds no buffer export that would stop an explicit close from unmapping it under the
        frame)."""
        self.stop.set()
        self.wake.set()
        self.conn.close()
        self.maps.clear()


class ChannelServer:
    """The receiving end of every channel into one actor: listens on :func:`channel_address`, authenticates each
    sender with the run's key and serves it on a thread of its own. ``deliver(d) -> replies`` is the actor's
    :meth:`~aerodaas.actors.data.plane.DataPlane.deliver`; it runs in the connection's thread (as a Ray actor call runs in one of the actor's
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
            conn = BufferedConnection(s.detach())
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
                    raw = conn.recv()
                except (EOFError, OSError):
                    return
                except Exception as e:  # noqa: BLE001 - not a wire tuple at all: not a peer of this version
                    self.failed += 1
                    self._on_error("channel", e)
                    return  # the sender sees the channel end and counts what it had in flight as failed
                try:
                    item = decode(raw)
                except Exception as e:  # noqa: BLE001 - e.g. a message of a class this process cannot import
                    self.failed += 1
                    self._on_error("channel", e)
                    seq = raw[1] if isinstance(raw, tuple) and len(raw) > 1 and type(raw[1]) is int else None
                    if seq is None:
                        return
                    send(encode_done(ChannelDone(seq, [], f"{type(e).__name__}: {e}", session.take_freed())))
                    continue
                raw = None
                if self._closed:  # read from the buffer after close(): the sender counts it failed, so hand nothing on
                    return
                if not isinstance(item, ChannelSend):
                    continue
                self.received += 1
                seq, d = item.seq, item.delivery
                meta = d.msg.meta  # a reply carrying this very FrameMeta says so instead (channel_wire.SAME_META)
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
    def _map(sf: SlotFrame, maps: dict[str, Mapped], freed: deque, wake: threading.Event,
             server_thread: int) -> np.ndarray:
        """The read-only array over slot ``sf`` (mapped once per slot); when the last reference to it goes, its
        name joins ``freed`` (never a send from a finalizer: it may run inside another send of this thread)."""
        shm = maps.get(sf.name)
        if shm is None:
            shm = maps[sf.name] = attach(sf.name)
        arr = np.ndarray(sf.shape, np.dtype(sf.dtype), buffer=shm.buf)
        arr.flags.writeable = False
        weakref.finalize(arr, _freed, freed, wake, sf.name, server_thread, shm)
        return arr

    def close(self) -> None:
        """Stop serving: the address is released and every sender's connection is closed (they count what they had
        in flight as failed)."""
        with self._conns_lock:
            self._closed = True
            conns = list(self._conns)
        for conn in conns:
            shutdown_connection(conn)
        if self._acceptor is not threading.current_thread():
            self._acceptor.join(2.0)  # it leaves accept() within its timeout; then the address is free at once
        self._sock.close()
