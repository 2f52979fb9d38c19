"""The recorder of an actor without the run's file: :class:`RemoteRecorder` batches its messages, numbered per
stream (:class:`~aerodaas.protocol.messages.RecordItem` ``seq``), to the run's recorder actor with its counts
(:class:`~aerodaas.protocol.messages.ProducerLedger`), from which the recording's accounting is made
(:mod:`aerodaas.recording.accounting`)."""
from __future__ import annotations

import dataclasses
import threading
import time
from typing import Any, Callable

import numpy as np

from aerodaas.protocol.messages import (ProducerLedger, RecordCamera, RecordDetections, RecordImage, RecordItem,
                                       RecordJson, RecordOdometry, RecordTracks)

__all__ = ["RemoteRecorder", "AnalyticsCounts", "AnalyticsAccounting", "FrameHold"]


class AnalyticsCounts:
    """The analytics counts of a :class:`~aerodaas.protocol.messages.ProducerLedger` kept by one process: items
    offered to each analytics component per robot, items each of its analytics took without a recorded output, the
    analytics' names. Thread-safe (one internal lock): analytics threads count while the sender snapshots."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.offered_to: dict[str, dict[str, int]] = {}
        self.without: dict[str, dict[str, int]] = {}
        self.names: dict[str, str] = {}

    def offered(self, cid: str, robot: str) -> None:
        """One item offered to component ``cid`` for ``robot``."""
        with self._lock:
            per = self.offered_to.setdefault(str(cid), {})
            per[robot] = per.get(robot, 0) + 1

    def no_output(self, cid: str, name: str, robot: str) -> None:
        """One item of ``robot`` that analytics ``name`` of component ``cid`` took without a recorded output."""
        with self._lock:
            if name:  # "": a sender's count (an item its outlet shed), the analytics names itself
                self.names[str(cid)] = name
            per = self.without.setdefault(str(cid), {})
            per[robot] = per.get(robot, 0) + 1

    def declare(self, cid: str, name: str) -> None:
        """Component ``cid`` records under ``/<robot>/<name>``."""
        with self._lock:
            self.names[str(cid)] = name

    def snapshot(self) -> tuple[dict, dict, dict]:
        """(offered_to, no_output, names), copied."""
        with self._lock:
            return ({k: dict(v) for k, v in self.offered_to.items()},
                    {k: dict(v) for k, v in self.without.items()}, dict(self.names))


class AnalyticsAccounting:
    """The accounting calls an analytics component makes on its recorder (the run's
    :class:`~aerodaas.actors.recording.recorder.RecorderService` in the recorder actor's process, a :class:`RemoteRecorder`
    elsewhere), kept in :attr:`analytics_counts`, which the subclass creates in its ``__init__``."""

    analytics_counts: AnalyticsCounts

    def count_offered(self, cid: str, robot: str) -> None:
        """One item handed to analytics component ``cid`` for ``robot`` (its outputs are accounted against it)."""
        self.analytics_counts.offered(cid, robot)

    def count_no_output(self, cid: str, name: str, robot: str) -> None:
        """Analytics ``name`` (component ``cid``) took an item of ``robot`` without recording an output."""
        self.analytics_counts.no_output(cid, name, robot)

    def declare_analytics(self, cid: str, name: str) -> None:
        """Analytics component ``cid`` of this actor records under ``/<robot>/<name>``."""
        self.analytics_counts.declare(cid, name)


class FrameHold:
    """How long a simulated run's clock may still wait for its recorder: ``budget_s`` wall seconds in all
    (:attr:`aerodaas.config.SimulationConfig.recorder_hold_s`), of which :attr:`held_s` are spent. A recorder's
    ``image`` calls :meth:`wait` on the clock's thread before it would drop a frame, so simulated time waits instead
    (the actor's clock takes the time waited off its pacing, :meth:`aerodaas.actors.host.assembly.ActorAssembly.run`)."""

    def __init__(self, budget_s: float = 0.0) -> None:
        self.budget_s = max(0.0, float(budget_s))
        self.held_s = 0.0
        self._since: float | None = None  # time.monotonic() at the start of the wait in progress
        self._seen = threading.Lock()  # held_s and _since change together for spent_s

    def spent_s(self) -> float:
        """Wall seconds waited so far, the wait in progress included (any thread may ask; :attr:`held_s` counts a
        wait only once it is over)."""
        with self._seen:
            since, held = self._since, self.held_s
        return held + (0.0 if since is None else max(0.0, time.monotonic() - since))

    def wait(self, room: threading.Condition, ready: Callable[[], bool], poll_s: float = 0.1) -> None:
        """Wait on ``room`` (its lock held by the caller) until ``ready()`` or the budget is spent."""
        if ready() or self.held_s >= self.budget_s:
            return
        with self._seen:
            t0 = self._since = time.monotonic()
        try:
            while not ready():
                left = self.budget_s - self.held_s - (time.monotonic() - t0)
                if left <= 0:
                    return
                room.wait(min(poll_s, left))
        finally:
            with self._seen:
                self.held_s += time.monotonic() - t0
                self._since = None


class RemoteRecorder(AnalyticsAccounting):
    """The recorder of an actor without one (e.g. the cloud actor of analytics deployed on cloud compute): the same
    non-blocking producer calls as :class:`RecorderService` (``detections``, ``json``, ``odometry``, ``camera``;
    frames are not sent), batched and delivered to the recorder of actor ``target`` (the edge actor) through its
    ``record`` actor method, at most every ``period_s`` seconds from a background thread. :meth:`close` delivers
    what is left and waits for it. ``plane`` is this process's :class:`~aerodaas.actors.data.plane.DataPlane` (its ``peers`` are known once
    the actors are connected).
    Delivery failures are counted in ``send_errors`` (the run goes on; the recording then lacks those messages).

    Every item is numbered on its stream when offered (a frame dropped here too: its number is never recorded, a
    gap the accounting counts); numbers go on from this actor's count the recorder actor holds (a restarted actor
    asks for it before its first batch, :meth:`_base`), and each batch carries this actor's counts so far
    (:class:`~aerodaas.protocol.messages.ProducerLedger`).

    Memory is bounded while the recorder does not answer (stopped, starved, restarting): at most
    ``max_in_flight_frames`` JPEG frames are in batches the recorder actor has not yet taken; past that, batches wait
    here (their frames count against ``max_pending_frames``), and further frames are dropped and counted. Before,
    Ray's queue to a stopped recorder actor grew without bound, and whether a 20 s recorder stall lost frames
    depended on whether this process had asked for its base counts before the stall.

    ``hold_s``: in a simulated run, how long in all (wall seconds) :meth:`image` may wait for room instead of
    dropping a frame (the caller is the clock's thread, so simulated time waits with it); the time waited is in
    ``hold.held_s``. 0: drop at once (real vehicles, video streams)."""

    def __init__(self, plane: Any, target: str = "recorder", period_s: float = 0.1, jpeg_quality: int = 80,
                 max_pending_frames: int = 256, max_pending_bytes: int = 256 << 20,
                 max_in_flight_frames: int = 64, hold_s: float = 0.0) -> None:
        self.plane, self.target, self.period_s = plane, target, period_s
        self.jpeg_quality, self.max_pending_frames = jpeg_quality, max_pending_frames
        self.max_pending_bytes = max_pending_bytes
        self.max_in_flight_frames = max(1, int(max_in_flight_frames))
        self.held_batches = 0  # sends put off because max_in_flight_frames were not yet taken by the recorder
        self._pending_frames = 0
        self._pending_bytes = 0
        self._buf: list[RecordItem] = []
        self._lock = threading.Lock()
        self._room = threading.Condition(self._lock)  # notified when a batch leaves the buffer (:meth:`_send`)
        self.hold = FrameHold(hold_s)
        self._refs: list[tuple[Any, int]] = []  # (ObjectRef of a record call, frames in its batch)
        self._offered: dict[str, int] = {}  # stream -> items numbered by this process (before adding _base)
        self.analytics_counts = AnalyticsCounts()  # analytics inputs offered / taken without output, by this process
        self._base_ledger: ProducerLedger | None = None  # this actor's counts before this process
        self._ledger_sent: Any = None  # the counts as of the last batch sent
        self.sent = 0
        self.send_errors: list[str] = []
        self.frames_dropped = 0
        #: CPU seconds of the JPEG encodes of recorded frames in this process (``time.thread_time`` of the sending
        #: thread around them)
        self.encode_cpu_s = 0.0
        self.closed = False
        #: the same interface as :class:`RecorderService`: a disk failure is the edge recorder's (the file is there),
        #: so these callbacks are never called here
        self.on_failure: list[Callable[[dict], None]] = []
        self._wake = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="aerodaas-remote-recorder", daemon=True)
        self._thread.start()

    def image(self, topic: str, t_ns: int, frame: np.ndarray, frame_id: str) -> bool:
        """Queue a (H, W, 3) uint8 BGR frame (shared, not copied); it is JPEG-encoded here, on the sending thread,
        and crosses to the recorder as JPEG bytes. At most ``max_pending_frames`` frames of at most
        ``max_pending_bytes`` bytes in all wait (a sending thread starved for a second or two under load loses
        none: 8 frames per 0.1 s lost 159 of 412 at --speedup 20 on a loaded 2-core machine); beyond that a frame
        is dropped and counted (False): a gap in its topic's sequence numbers, lost in the accounting."""
        size = int(getattr(frame, "nbytes", None) or len(frame))
        with self._lock:
            item = self._number(RecordImage(topic, t_ns, frame, frame_id))
            self.hold.wait(self._room, lambda: self.closed or not self._full(size))
            if self.closed or self._full(size):
                self.frames_dropped += 1
                return False
            self._pending_frames += 1
            self._pending_bytes += size
            self._buf.append(item)
        return True

    def _full(self, size: int) -> bool:
        """No room for a frame of ``size`` bytes (caller holds the lock)."""
        return self._pending_frames >= self.max_pending_frames or self._pending_bytes + size > self.max_pending_bytes

    def camera(self, robot: str, sensor: str, intrinsics: dict, pitch_deg: float) -> None:
        self._put(RecordCamera(robot, sensor, dict(intrinsics), float(pitch_deg)))

    def detections(self, topic: str, t_ns: int, dets: list, image_size: tuple[int, int] | None = None) -> None:
        self._put(RecordDetections(topic, t_ns, list(dets), image_size))

    def odometry(self, robot: str, t_ns: int, odom: dict) -> None:
        self._put(RecordOdometry(robot, t_ns, odom))

    def tracks(self, prefix: str, t_ns: int, robot: str, rows: list, image_size: tuple[int, int] | None = None) -> None:
        self._put(RecordTracks(prefix, t_ns, robot, list(rows), image_size))

    def json(self, topic: str, t_ns: int, obj: dict, schema_name: str) -> None:
        self._put(RecordJson(topic, t_ns, obj, schema_name))

    def _put(self, item: RecordItem) -> None:
        with self._lock:
            if not self.closed:
                self._buf.append(self._number(item))

    def _number(self, item: RecordItem) -> RecordItem:
        """``item`` numbered within this process on its stream (caller holds the lock; :meth:`_send` adds the
        actor's count from before this process)."""
        stream = item.stream()
        if stream is None:
            return item
        n = self._offered.get(stream, 0)
        self._offered[stream] = n + 1
        return item.numbered(n)

    def _base(self) -> ProducerLedger | None:
        """This actor's counts from before this process (its earlier incarnations', kept by the recorder actor;
        empty for a first start) and this process's incarnation number (its ``incarnation``, carried by every item
        and ledger it sends: the recorder's duplicate rule is keyed by it), asked once; None while the recorder
        actor does not answer (asked again at the next batch, which waits until then)."""
        import ray  # lazy: heavy ray

        if self._base_ledger is None:
            try:
                self._base_ledger = ray.get(self.plane.peer(self.target).ledger_of.remote(self.plane.actor_id),
                                            timeout=10)
            except Exception as e:  # noqa: BLE001 - the recorder busy or restarting: try again with the next batch
                self.send_errors.append(f"ledger: {type(e).__name__}: {e}")
                return None
        return self._base_ledger

    @property
    def frames_in_flight(self) -> int:
        """Frames in batches sent to the recorder actor and not yet answered (at most ``max_in_flight_frames`` plus
        one batch's)."""
        return sum(n for _, n in self._refs)

    def _reap(self) -> None:
        """Forget the record calls the recorder actor has answered (their errors into ``send_errors``)."""
        import ray  # lazy: heavy ray

        if not self._refs:
            return
        done, _ = ray.wait([r for r, _ in self._refs], num_returns=len(self._refs), timeout=0)
        for ref in done:
            try:
                ray.get(ref)
            except Exception as e:  # noqa: BLE001
                self.send_errors.append(f"{type(e).__name__}: {e}")
        answered = set(done)
        self._refs = [(r, n) for r, n in self._refs if r not in answered]

    def _send(self, hold: bool = True) -> None:
        """Send what waits as one batch (frames JPEG-encoded here). ``hold``: not while ``max_in_flight_frames``
        frames are in batches the recorder has not answered (what waits stays here; :meth:`image` drops beyond
        ``max_pending_frames``)."""
        from aerodaas.actors.data.plane import encode_frame  # lazy: heavy cv2, ray

        self._reap()
        if hold and self.frames_in_flight >= self.max_in_flight_frames:
            self.held_batches += 1
            return
        base = self._base()
        if base is None:
            return
        with self._lock:
            batch, self._buf = self._buf, []
            frames, self._pending_frames, self._pending_bytes = self._pending_frames, 0, 0
            self._room.notify_all()
            ledger = base.plus(dict(self._offered), *self.analytics_counts.snapshot())
        if not batch and ledger == self._ledger_sent:
            return
        self._ledger_sent = ledger
        batch = [(it.numbered(base.produced.get(it.stream() or "", 0) + it.seq) if getattr(it, "seq", -1) >= 0
                  else it).of_incarnation(base.incarnation) for it in batch]
        if frames:  # the one JPEG encode of each recorded frame, off the camera's thread
            c0 = time.thread_time()
            batch = [dataclasses.replace(it, frame=encode_frame(it.frame, self.jpeg_quality))
                     if isinstance(it, RecordImage) and isinstance(it.frame, np.ndarray) else it for it in batch]
            self.encode_cpu_s += time.thread_time() - c0
            copies = getattr(self.plane, "copies", None)
            if copies is not None:
                copies.count("recorder_jpeg_encoded", frames)
        try:
            self._refs.append((self.plane.peer(self.target).record.remote(batch, ledger), frames))
            self.sent += len(batch)
        except Exception as e:  # noqa: BLE001 - reported in stats, never fatal
            self.send_errors.append(f"{type(e).__name__}: {e}")

    def _loop(self) -> None:
        while not self._wake.wait(self.period_s):
            self._send()

    def report(self) -> dict[str, Any]:
        """``{"failure": None, "lost": 0, "frames_dropped": n, "write_errors": [...]}`` like
        :meth:`RecorderService.report`; batches that could not be delivered are in ``write_errors``."""
        return {"failure": None, "lost": 0, "frames_dropped": self.frames_dropped,
                "write_errors": self.send_errors[-10:]}

    def close(self, timeout_s: float = 30.0) -> dict[str, Any]:
        """Deliver the rest and wait (at most ``timeout_s``) until the edge recorder has queued it all."""
        import ray  # lazy: heavy ray

        if not self.closed:
            self._wake.set()
            self._thread.join(timeout_s)
            self._send(hold=False)
            self.closed = True
            try:
                ray.get([r for r, _ in self._refs], timeout=timeout_s)
            except Exception as e:  # noqa: BLE001
                self.send_errors.append(f"{type(e).__name__}: {e}")
            self._refs = []
        return {}
