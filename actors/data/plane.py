"""The data plane inside one actor of a run: its components hand items to each other in memory, and items for
components of other actors leave through outlets.

Every component of an application — a drone (its vehicle backend, flight logic, odometry and stat-stream
sensors), a camera, an analytics, a trajectory scheduler — lives in one of the run's Ray actors (a drone actor, an
analytics actor, a dispatcher actor; :mod:`aerodaas.runtime.dataflow` decides which). Each actor holds one :class:`DataPlane`:

* a component is a *mailbox actor* (:class:`Component`): it processes one item at a time, in order; an item
  for an idle component runs **in the delivering thread** (no thread hop, no serialisation, no copy: a frame
  is the same ``ndarray`` object from the camera to the last colocated analytics); an item for a busy component
  is queued up to its stream ``buffer`` (then dropped and counted, so a slow consumer never stalls the camera or
  the control loop); items waiting for an analytics that takes batches go to it in one call;
* in a drone actor the clock thread (:class:`~aerodaas.actors.host.assembly.ActorAssembly`) steps every vehicle, publishes
  odometry and the stat-stream, triggers camera captures and runs each drone's control ticks; it never runs
  components itself: it submits work to a small thread pool (OpenCV and onnxruntime release the GIL, so renders
  and inference overlap on 2 cores);
* when an analytics hands navigation to a drone's navigation inbox, the drone applies it at once (not at its next
  control tick), so the end-to-end latency ends at the command reaching the vehicle backend.

Items for a component of another actor (:class:`~aerodaas.protocol.messages.Message` kinds, typed) leave through that
edge's outlet, bounded in flight: a same-node channel when the other actor serves one on this machine
(:mod:`aerodaas.actors.data.channel`: the frame copied once into shared memory, the message and its reply on a Unix socket), else a
Ray actor call (:class:`RemoteOutlet`: the frame put once into the object store on one tier, JPEG-encoded across
tiers). Outputs bound for the sender come back in the reply of the same delivery.

Frame copies per frame (counted in :class:`FrameCopies`, ``DataPlane.copies``, reported in the actor's stats as
``frame_copies``): the camera materialises the pixels once (render, or the vehicle's decoded video, or a
recording's decoded JPEG); from there **0 copies** to every reader in the same actor (follow analytics, scheduler
and drone get detections and navigation, not pixels); **+1 JPEG encode** when the run is recorded (in the
recorder's writer thread, or the sending actor's for the run's recorder actor); **+1 copy** into a channel slot
per delivery to another actor on the same machine (read in place there); **+1 JPEG encode on the sending actor
and +1 decode on the receiving one** per edge that crosses tiers; +1 ``ray.put`` per delivery to an actor of the
same tier on another machine (or with ``same_node_transport: ray``; the receiver's ``ray.get`` maps the object
store's shared memory on its node).

Lock-step is a property of the clock, not of the transport: with ``lockstep`` the clock waits after every frame
(and odometry message) for its whole cascade — every item derived from it, in this actor and in others — before
simulated time moves on (:class:`Cascade`). Items travel over the same outlets either way (a same-node channel, or
Ray calls across nodes and tiers); an item that belongs to a cascade is never dropped (the clock bounds what is in
flight) and its delivery is answered only once the receiver's own cascade for it is done
(:attr:`~aerodaas.protocol.messages.Delivery.cascade`): the sender's cascade stays open until that answer arrived and
the replies in it were handed on.
"""
from __future__ import annotations

import gc
import os
import sys
import threading
import time
import traceback
from collections import deque
from dataclasses import dataclass
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable

import numpy as np
import ray

from aerodaas.actors.data.cascade import Cascade
from aerodaas.actors.data.channel import channel_address
from aerodaas.actors.data.channel_outlet import ChannelOutlet
from aerodaas.actors.data.frames import FrameCopies, decode_frame, encode_frame
from aerodaas.actors.data.remote_outlet import RemoteOutlet
from aerodaas.protocol.messages import Delivery, EncodedFrame, FrameMsg, Message, Port
from aerodaas.protocol.startup_probe import probe

__all__ = ["Cascade", "Component", "FrameCopies", "RemoteOutlet", "DataPlane", "Settled", "encode_frame",
           "decode_frame"]


@dataclass(frozen=True)
class Settled:
    """What :meth:`DataPlane.settle` found: ``idle`` — nothing was left in flight when it returned (False: its
    time ran out); ``waited`` — something was in flight when it was called (a message it then handed on may have
    given another actor work: settle again until no actor waited)."""

    idle: bool
    waited: bool


def percentiles(values: list[float]) -> dict[str, float]:
    """``{"median", "p99", "n"}`` of ``values`` (0.0 for an empty list)."""
    a = np.asarray(values if values else [0.0], float)
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "n": len(values)}


class Component:
    """A mailbox actor inside a :class:`DataPlane`: :meth:`offer` runs :meth:`handle` at once in the caller's thread
    when the component is idle, queues the item when it is busy (up to ``buffer - 1`` waiting items; unbounded in
    lock-step), and drops it otherwise (counted in ``dropped``); the thread that is processing drains the queue,
    in order. :meth:`handle` returns the envelopes to publish downstream (or None); when nothing waits the
    component is released before they are published, so a slow subscriber never keeps its producer busy. An
    exception in :meth:`handle` or while publishing is recorded and counted in ``errors``; the mailbox keeps
    draining. Subclasses override :meth:`handle`. Thread-safe."""

    kind = "component"

    def __init__(self, plane: "DataPlane", cid: str, buffer: int = 1) -> None:
        self.plane, self.cid = plane, cid
        self.capacity = max(0, int(buffer) - 1)
        self._m = threading.Lock()
        self._busy = False
        self._q: deque = deque()
        self.received = 0
        self.dropped = 0
        self.errors = 0

    def offer(self, port: Port, msg: Message) -> bool:
        """Deliver one message; returns False when it was dropped (the component is busy and its queue full)."""
        tok = msg.tok
        with self._m:
            self.received += 1
            if self._busy:
                if tok is not None or len(self._q) < self.capacity:
                    self._q.append((port, msg))
                    if tok is not None:
                        tok.add()
                    return True
                self.dropped += 1
                return False
            self._busy = True
            if tok is not None:
                tok.add()
        self._run(port, msg)
        return True

    def _run(self, port: Port, msg: Message) -> None:
        """Process ``msg``, hand its outputs on, then keep draining the mailbox in this thread until it is empty
        (resubmitting each waiting item to the pool would queue it behind every pending capture: starvation)."""
        while True:
            batch = [(port, msg)]
            limit = self.batch_limit()
            if limit > 1:  # items waiting (e.g. frames of several drones for one detector): one call for them
                with self._m:
                    while self._q and len(batch) < limit:
                        batch.append(self._q.popleft())
            try:
                outs = self.handle_batch(batch) if len(batch) > 1 else [self.handle(port, msg)]
            except Exception as e:  # a failing component never takes the actor down: recorded, counted, skipped
                self.errors += 1
                outs = [None] * len(batch)
                self.plane.report_error(self.cid, e)
            with self._m:
                nxt = self._q.popleft() if self._q else None
                if nxt is None:
                    self._busy = False
            for (_, m_in), out in zip(batch, outs):
                try:
                    if out:
                        self.plane.publish(self.cid, out, m_in.tok)
                except Exception as e:  # a failing subscriber must not leave this mailbox busy with items queued
                    self.errors += 1
                    self.plane.report_error(self.cid, e)
                finally:
                    if m_in.tok is not None:
                        m_in.tok.done()
            if nxt is None:
                return
            port, msg = nxt

    def handle(self, port: Port, msg: Message) -> list[Message] | None:
        """Process one message; return the messages to publish (or None)."""
        return None

    def batch_limit(self) -> int:
        """How many waiting items :meth:`handle_batch` may take at once (1: no batching, the default)."""
        return 1

    def handle_batch(self, items: list[tuple[Port, Message]]) -> list[list[Message] | None]:
        """Process several ``(port, message)`` items in one go; one result per item, in order (default: one
        :meth:`handle` call each)."""
        return [self.handle(p, m) for p, m in items]

    def mailbox_stats(self) -> dict:
        return {"received": self.received, "dropped": self.dropped, "errors": self.errors}

    def busy(self) -> bool:
        """True while a message is being handled or waits in the mailbox."""
        with self._m:
            return self._busy or bool(self._q)


class DataPlane:
    """One actor's share of a run: its components, the routes between them, the outlets to other actors and the
    worker pool. Plain Python: :class:`~aerodaas.actors.host.base.ActorBase` is the Ray actor around it.

    ``routes`` maps a producing component id to its subscribers ``[(component id, port, buffer)]``; components
    of other actors are reached through ``peers`` (actor id -> actor handle) and ``location`` (component id ->
    actor id). ``tier`` decides whether a frame sent to a peer of another tier is JPEG-encoded."""

    def __init__(self, actor_id: str, tier: str, epoch_ns: int, workers: int | None = None,
                 recorder: Any = None, restart_hold_s: float = 60.0) -> None:
        self.actor_id, self.tier, self.epoch_ns = actor_id, tier, epoch_ns
        n = workers or max(2, min(4, (os.cpu_count() or 2)))
        self.workers = n  #: threads of the worker pool
        self.pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix=f"aerodaas-{actor_id}")
        self.components: dict[str, Component] = {}
        self.routes: dict[str, list[tuple[str, Port, int, tuple | None]]] = {}
        self.location: dict[str, str] = {}
        self.tiers: dict[str, str] = {actor_id: tier}
        self.peers: dict[str, Any] = {}
        self._outlets: dict[tuple[str, str, Port], Any] = {}  # RemoteOutlet or channel_outlet.ChannelOutlet
        #: the run's channel key (bytes) when actors on this machine talk through same-node channels
        #: (:mod:`aerodaas.actors.data.channel`); None: Ray calls only (``same_node_transport: ray``)
        self.channel_key: bytes | None = None
        #: lock-step: how long (s) a frame for a consumer actor that died waits for its restart
        #: (``ActorSpec.restart_hold_s``, the environment's ``actor_restart_timeout_s``)
        self.restart_hold_s = float(restart_hold_s)
        self._tl = threading.local()  # .reply: (actor id of the caller, [Delivery]) while a deliver runs
        self.recorder = recorder
        self.copies = FrameCopies()
        self.errors: list[dict] = []
        self.first_processed_wall: float | None = None
        self._closed = False
        self._queued = 0  # pool jobs submitted and not yet finished (see settle)
        self._queued_lock = threading.Lock()
        self.gc_pauses_ms: list[float] = []
        self._gc_t0 = 0.0

    def watch_gc(self) -> None:
        """Freeze what setup allocated (long-lived: models, textures, configs) out of the collector's sight and
        time every collection from now on (``gc_pauses_ms``): a full collection stalls every thread."""
        gc.collect()
        gc.freeze()

        def cb(phase: str, info: dict) -> None:
            if phase == "start":
                self._gc_t0 = time.perf_counter()
            elif info.get("generation", 0) >= 1:
                self.gc_pauses_ms.append((time.perf_counter() - self._gc_t0) * 1e3)

        gc.callbacks.append(cb)

    # ------------------------------------------------------------------ wiring
    def add(self, comp: Component) -> Component:
        self.components[comp.cid] = comp
        self.location[comp.cid] = self.actor_id
        return comp

    def connect(self, routes: dict, location: dict, tiers: dict, peers: dict) -> None:
        """``routes``: producer id -> ``[(consumer id, port, buffer, robots or None)]``; ``location``: component id
        -> actor id; ``tiers``: actor id -> tier; ``peers``: actor id -> Ray actor name (resolved on first use, so a
        restarted actor is reached under the same name) or actor handle."""
        self.routes = {k: [tuple(s) if len(s) == 4 else (*s, None) for s in v] for k, v in routes.items()}
        merged = dict(location)  # the plan's typed ids (ComponentId: kind, robot) are the keys kept
        for cid, hid in self.location.items():
            merged.setdefault(cid, hid)
        self.location = merged
        self.tiers.update(tiers)
        self.peers = dict(peers)

    def peer(self, actor_id: str) -> Any:
        """The actor handle of actor ``host_id`` (looked up by name once, then cached). Raises KeyError."""
        p = self.peers[actor_id]
        if isinstance(p, str):
            p = self.peers[actor_id] = ray.get_actor(p)
        return p

    # ------------------------------------------------------------------ delivery
    def submit(self, fn: Callable, *args: Any) -> None:
        if not self._closed:
            self._pool_submit(self._guard, fn, *args)

    def _pool_submit(self, job: Callable, *args: Any) -> None:
        """Queue ``job(*args)`` on the pool, counted in ``_queued`` until it ran (see :meth:`settle`)."""
        with self._queued_lock:
            self._queued += 1
        try:
            self.pool.submit(self._counted, job, *args)
        except RuntimeError:  # the pool shut down meanwhile (closing): the job never runs
            with self._queued_lock:
                self._queued -= 1
            raise

    def _counted(self, job: Callable, *args: Any) -> None:
        try:
            job(*args)
        finally:
            with self._queued_lock:
                self._queued -= 1

    def _guard(self, fn: Callable, *args: Any) -> None:
        try:
            fn(*args)
        except Exception as e:  # pool jobs must never die silently
            self.report_error(getattr(fn, "__qualname__", str(fn)), e)

    def busy(self) -> bool:
        """True while anything of this actor is in flight: a pool job queued or running, a component handling or
        holding a message, an outlet's call or channel delivery not yet answered."""
        with self._queued_lock:
            if self._queued:
                return True
        return (any(c.busy() for c in list(self.components.values()))
                or any(o.busy() for o in list(self._outlets.values())))

    def settle(self, timeout_s: float, poll_s: float = 0.01) -> Settled:
        """Wait (at most ``timeout_s`` seconds) until nothing of this actor is in flight (:meth:`busy`), so that
        its counts include every message it sent or received: a frame still on its way to a consumer when the
        drones stopped is then counted by that consumer too, not lost between the two reports. The producers must
        have stopped first (else this may wait the whole ``timeout_s``)."""
        deadline = time.monotonic() + max(0.0, timeout_s)
        waited = False
        while self.busy():
            waited = True
            if time.monotonic() >= deadline:
                return Settled(idle=False, waited=True)
            time.sleep(poll_s)
        return Settled(idle=True, waited=waited)

    def publish(self, src: str, msgs: list[Message], tok: Cascade | None = None, inline: bool = True) -> None:
        """Hand ``msgs`` (outputs of component ``src``) to every subscriber. Local subscribers: the last one runs
        in this thread when ``inline`` (zero hops for a chain), the others on the pool; remote ones through their
        outlet on the pool (JPEG encoding stays off the hot path) — a same-node channel's in this thread when
        ``inline`` and no local subscriber takes the item — or in the reply of the deliver call this thread is
        answering. ``tok``: the lock-step cascade the messages join (it stays open until each is handed on)."""
        subs = self.routes.get(src)
        if not subs:
            return
        for msg in msgs:
            if tok is not None:
                msg.tok = tok
            local = []
            remote = []
            robot = msg.robot
            rec = self.recorder
            for cid, port, buf, only in subs:
                if only is not None and robot not in only:
                    continue  # an edge to a replica or a drone's own copy carries only its drones' items
                if rec is not None and getattr(cid, "kind", None) == "analytics":
                    rec.count_offered(cid, robot)  # its outputs are accounted against it (recording accounting)
                comp = self.components.get(cid)
                if comp is not None:
                    local.append((comp, port))
                elif not self._reply_to(cid, port, msg):  # else: returned to the caller in its deliver's reply
                    remote.append(self._outlet(src, cid, port, buf))
            # a same-node channel's send is a copy into its shared-memory slot and a socket write: made in this thread
            # when nothing of this actor reads the item after it (no pool hop for a frame bound for an analytics
            # actor: a thread wake-up less per frame); a Ray outlet (it may JPEG-encode), or one publishing thread
            # that must not wait (``inline`` False: the clock's), or local readers waiting behind it: on the pool
            now = inline and not local
            for o in remote:
                if now and isinstance(o, ChannelOutlet):
                    self._guard(o.send, msg)
                else:
                    self.later(tok, o.send, msg)
            last = len(local) - 1
            for i, (comp, port) in enumerate(local):
                if inline and i == last:
                    comp.offer(port, msg)
                else:
                    self.later(tok, comp.offer, port, msg)

    def later(self, tok: Cascade | None, fn: Callable, *args: Any) -> None:
        """Run ``fn(*args)`` on the pool; ``tok`` (a lock-step cascade, or None) stays open until it ran."""
        if tok is None:
            self.submit(fn, *args)
            return
        tok.add()
        if self._closed:
            tok.done()
        else:
            self._pool_submit(self._then_done, tok, fn, *args)

    def _then_done(self, tok: Cascade, fn: Callable, *args: Any) -> None:
        try:
            self._guard(fn, *args)
        finally:
            tok.done()

    def _reply_to(self, cid: str, port: Port, msg: Message) -> bool:
        """While a deliver call from actor H runs in this thread, an item for a component of H goes back in that
        call's reply instead of a call of its own (not frames: their pixels never travel in a reply)."""
        rep = getattr(self._tl, "reply", None)
        if rep is None or isinstance(msg, FrameMsg) or self.location.get(cid) != rep[0]:
            return False
        item = msg.to_wire()
        item.trace["replied_wall"] = time.time()
        rep[1].append(Delivery(cid, port, item))
        return True

    def on_reply(self, items: list[Delivery], inline: bool = False) -> None:
        """Items another actor returned in a deliver call's reply (each message's ``tok``: the cascade of the call
        it answers, set by the outlet): offered to their components on the pool, or in this thread when ``inline``
        (a channel's reader thread; never Ray's callback thread, which must not block)."""
        now = time.time()
        for d in items:
            tr = d.msg.trace
            if "replied_wall" in tr:
                tr["reply_ms"] = (now - tr.pop("replied_wall")) * 1e3
            comp = self.components.get(d.cid)
            if comp is None:
                continue
            if inline:
                comp.offer(d.port, d.msg)
            else:
                self.later(d.msg.tok, comp.offer, d.port, d.msg)

    def frame_buffer(self, src: str, shape: tuple[int, ...], robot: str) -> np.ndarray | None:
        """A writable ``shape`` uint8 array to make component ``src``'s next frame (of ``robot``) in: a slot lent by
        the same-node channel of its first subscriber in another actor on this machine that takes ``robot``'s items
        (:meth:`aerodaas.actors.data.channel_outlet.ChannelOutlet.lend`; that outlet then sends the frame without copying it; every
        other reader reads it as any frame). None when no such subscriber is reached by a channel, its slots are
        held, or its outlet cannot be made now (the frame is then made as usual, and publishing it reports why)."""
        for cid, port, buf, only in self.routes.get(src, ()):
            if cid in self.components or (only is not None and robot not in only):
                continue
            try:
                o = self._outlet(src, cid, port, buf)
            except Exception:  # noqa: BLE001 - no route or peer yet: publish() meets and reports it
                continue
            if isinstance(o, ChannelOutlet):
                return o.lend(shape)
        return None

    def _outlet(self, src: str, cid: str, port: Port, buffer: int) -> Any:
        """The outlet of edge ``src`` -> ``cid`` (another actor's component), made on first use: a same-node
        channel when the peer serves one on this machine (:mod:`aerodaas.actors.data.channel`), else Ray calls
        (:class:`RemoteOutlet`). Raises KeyError for a component no actor of the run has."""
        key = (src, cid, port)
        o = self._outlets.get(key)
        if o is None:
            hid = self.location.get(cid)
            if hid is None or hid not in self.peers:
                raise KeyError(f"actor {self.actor_id!r}: no route to component {cid!r} (subscriber of {src!r})")
            o = self._channel_outlet(hid, cid, port, buffer)
            if o is None:
                o = RemoteOutlet(self.peer(hid), cid, port, buffer, jpeg=self.tiers.get(hid, self.tier) != self.tier,
                                 copies=self.copies, reply_to=self.actor_id, on_reply=self.on_reply,
                                 hold_s=self.restart_hold_s)
            rec = self.recorder
            if rec is not None and getattr(cid, "kind", None) == "analytics":  # load shed: taken without output
                o.on_shed = lambda msg, cid=cid: rec.count_no_output(cid, "", msg.robot)
            self._outlets[key] = o
        return o

    def _channel_outlet(self, hid: str, cid: str, port: Port, buffer: int) -> Any:
        """A :class:`~aerodaas.actors.data.channel_outlet.ChannelOutlet` to actor ``hid`` when channels are on and ``hid`` serves one on this
        machine (same tier only: frames cross tiers as JPEG through Ray); None otherwise."""
        if self.channel_key is None or self.tiers.get(hid, self.tier) != self.tier:
            return None

        try:
            return ChannelOutlet(channel_address(self.channel_key, hid), self.channel_key, cid, port, buffer,
                                 reply_to=self.actor_id, on_reply=lambda items: self.on_reply(items, inline=True),
                                 copies=self.copies, hold_s=self.restart_hold_s)
        except Exception:  # noqa: BLE001 - not on this machine (or not serving): Ray calls
            return None

    def deliver(self, d: Delivery, answer: Callable[[list], None] | None = None) -> list | None:
        """A message from another actor. A frame's pixels arrive as JPEG bytes or an ObjectRef and are decoded (or
        mapped) once here. Returns the replies (Delivery items for the sender's components, see
        :class:`~aerodaas.protocol.messages.Delivery`) once the message was handed to its component.

        A delivery the sender's lock-step cascade waits for (``d.cascade``) is answered only when the cascade it
        starts here is done (every item derived from it, here and in the actors it reached): with ``answer``
        (a channel: its reader thread never blocks) this returns None and ``answer(replies)`` is called then, in
        the thread that finished the cascade; without (a Ray call) this blocks until then and returns the replies.
        Raises KeyError for an unknown component, TimeoutError after 120 s of a cascade that does not end."""
        msg = d.msg
        t_arrived = time.time()
        if isinstance(msg, FrameMsg):
            if isinstance(msg.data, EncodedFrame):
                msg.data = decode_frame(msg.data.jpeg)
                self.copies.count("tier_jpeg_decoded")
            elif isinstance(msg.data, ray.ObjectRef):
                msg.data = ray.get(msg.data)
                self.copies.count("object_store_get")
            if "sent_wall" in msg.trace:
                msg.trace.update(call_ms=(t_arrived - msg.trace["sent_wall"]) * 1e3,
                                 get_ms=(time.time() - t_arrived) * 1e3)
        comp = self.components[d.cid]
        if not d.cascade:
            return self._offer(comp, d)
        replies: list = []
        finished = threading.Event()

        def on_done() -> None:
            if answer is None:
                finished.set()
            else:
                answer(replies)

        tok = Cascade(on_done=on_done, hold=True)
        msg.tok = tok
        try:
            replies.extend(self._offer(comp, d))
        finally:
            tok.done()  # the hold: from here the last derived item to finish answers
        if answer is not None:
            return None
        if not finished.wait(120.0):
            raise TimeoutError(f"lock-step: a delivery to {d.cid!r} still had {tok.outstanding} items in flight "
                               f"after 120 s")
        return replies

    def _offer(self, comp: Component, d: Delivery) -> list:
        """Offer ``d`` to ``comp`` in this thread, collecting the items for the sender's components (``reply_to``)
        into the returned list."""
        if d.reply_to is None:
            comp.offer(d.port, d.msg)
            return []
        self._tl.reply = (d.reply_to, [])
        try:
            comp.offer(d.port, d.msg)
            return list(self._tl.reply[1])
        finally:
            self._tl.reply = None

    # ------------------------------------------------------------------ bookkeeping
    def report_error(self, where: str, e: BaseException) -> None:
        rec = {"where": where, "error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc(),
               "t_wall": time.time()}
        self.errors.append(rec)
        if len(self.errors) <= 5:
            print(f"aerodaas: error in {where}: {rec['error']}", file=sys.stderr, flush=True)

    def mark_processed(self) -> None:
        """Called by analytics when they finish an item: remembers the wall time of the first one (startup bench)."""
        if self.first_processed_wall is None:
            self.first_processed_wall = time.time()
            probe("first_processed")

    def lost_consumers(self) -> list[str]:
        """Ids of the consumers this actor's outlets gave up on: under lock-step their actor died and was not
        answering again within ``restart_hold_s`` (the run reports them lost)."""
        return sorted({str(o.cid) for o in list(self._outlets.values()) if o.lost})

    def outlet_stats(self, src: str) -> list[dict]:
        return [o.stats() for (s, _, _), o in self._outlets.items() if s == src]

    def close(self) -> None:
        self._closed = True
        self.pool.shutdown(wait=True, cancel_futures=True)
        for o in list(self._outlets.values()):
            close = getattr(o, "close", None)
            if callable(close):
                close()
