"""Typed messages of a run: what travels on an edge of the dataflow graph (between the components of one actor and
between actors), the deliveries actors send each other, and what they send the run's recorder.

* :class:`Port` — where an edge enters its consumer (an analytics input, or the priority port of a drone's
  navigation inbox ``<robot>/scheduler``, optionally ``replace``);
* :class:`Message` and its kinds — :class:`FrameMsg` (a camera frame), :class:`OdometryMsg`, :class:`StatMsg`
  (a stat-stream transition), :class:`DetectionsMsg`, :class:`NavigationMsg` and :class:`ValueMsg` (anything
  else an analytics outputs). Every message names the robot it belongs to and its simulated time, carries the
  :class:`~aerodaas.model.types.FrameMeta` of the frame it derives from (if any) and the frame's latency ``trace``;
* :class:`Delivery` — one message for one component of another actor (``DataPlane.deliver``), and the replies that
  come back in the same call; :class:`EncodedFrame` — a frame's pixels as JPEG bytes, the wire form across
  tiers (on one tier a frame's pixels travel as an ObjectRef or through a same-node channel,
  :mod:`aerodaas.actors.data.channel`);
* :class:`RecordItem` and its kinds — what an actor without the file sends the run's recorder actor.

Frames are (H, W, 3) uint8 BGR, read-only ``ndarray``s shared by every reader of one process (never copied there).
"""
from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
import pickle
from typing import Any, ClassVar, Literal

__all__ = ["Port", "Message", "FrameMsg", "OdometryMsg", "StatMsg", "DetectionsMsg", "NavigationMsg", "ValueMsg",
           "output_message", "EncodedFrame", "Delivery", "RecordItem", "RecordImage", "RecordCamera",
           "RecordDetections", "RecordOdometry", "RecordJson", "ProducerLedger"]


@dataclass(frozen=True)
class Port:
    """Where an edge enters its consumer: ``in`` (an analytics input) or ``priority`` (a drone's navigation inbox's
    input at ``priority``; lower wins; ``replace``: the first navigation from it aborts the queued missions,
    pattern 5 of the paper, §3)."""

    name: Literal["in", "priority"] = "in"
    priority: int | None = None
    replace: bool = False

    def wire(self) -> str:
        """The port for humans and JSON: ``in`` or ``priority:<n>[:replace]``."""
        if self.name == "in":
            return "in"
        return f"priority:{self.priority}" + (":replace" if self.replace else "")


@dataclass(eq=False)
class Message:
    """One item on an edge. ``robot``: the robot it belongs to; ``sim_t``: simulated seconds (its frame's capture
    time for derived items); ``data``: the payload (see each kind); ``meta``: the FrameMeta of the frame it derives
    from, or None; ``trace``: the frame's latency trace (``capture_wall``: ``time.time()`` when the pixels were
    ready, ``inference_ms``, ``post_ms``, and for an actor hop ``put_ms``/``call_ms``/``get_ms``/``reply_ms``);
    ``tok``: the lock-step :class:`~aerodaas.actors.data.plane.Cascade` it belongs to (None outside lock-step; never
    crosses an actor boundary: a delivery carries ``cascade`` instead)."""

    robot: str
    sim_t: float
    data: Any
    meta: Any = None
    trace: dict[str, float] = field(default_factory=dict)
    tok: Any = field(default=None, repr=False)

    #: the kind's name in recordings and statistics
    kind: ClassVar[str] = "value"

    def to_wire(self, data: Any = None) -> "Message":
        """A copy to send to another actor: without the lock-step token, with ``data`` in place of the payload
        when given (a frame's ObjectRef or JPEG), the trace copied."""
        return dataclasses.replace(self, data=self.data if data is None else data, trace=dict(self.trace), tok=None)


@dataclass(eq=False)
class FrameMsg(Message):
    """A camera frame: ``data`` is the read-only (H, W, 3) uint8 BGR ``ndarray`` in a process; between actors an
    ObjectRef (same tier), an :class:`EncodedFrame` (across tiers) or a same-node channel slot. ``ref``/``jpeg``
    keep the frame's object-store put and JPEG encode, so a frame sent to several actors is put (or encoded) once."""

    kind: ClassVar[str] = "frame"
    ref: Any = field(default=None, repr=False)
    jpeg: Any = field(default=None, repr=False)

    def to_wire(self, data: Any = None) -> "FrameMsg":
        out = super().to_wire(data)
        out.ref = out.jpeg = None
        return out


@dataclass(eq=False)
class OdometryMsg(Message):
    """An odometry sample: ``data`` is :class:`~aerodaas.model.types.Odometry` as a dict (ENU metres, m/s, degrees)."""

    kind: ClassVar[str] = "odometry"


@dataclass(eq=False)
class StatMsg(Message):
    """A stat-stream transition: ``data`` is ``{"robot", "state", "previous", "t"}`` (mission FSM states)."""

    kind: ClassVar[str] = "stat"


@dataclass(eq=False)
class DetectionsMsg(Message):
    """An analytics' detections: ``data`` is a list of :class:`~aerodaas.model.types.Detection` (pixel boxes)."""

    kind: ClassVar[str] = "detections"


@dataclass(eq=False)
class NavigationMsg(Message):
    """An analytics' navigation: ``data`` is an :class:`~aerodaas.model.types.AeroNavigation`."""

    kind: ClassVar[str] = "nav"


@dataclass(eq=False)
class ValueMsg(Message):
    """Any other analytics output (e.g. a monitor's dict)."""

    kind: ClassVar[str] = "value"


def output_message(out: Any, source: Message, trace: dict[str, float]) -> Message:
    """The message carrying analytics output ``out`` computed from ``source``: NavigationMsg for an
    AeroNavigation, DetectionsMsg for a list of Detection (or an empty list), ValueMsg otherwise."""
    from aerodaas.model.types import AeroNavigation, Detection  # lazy: heavy pydantic

    if isinstance(out, AeroNavigation):
        cls: type[Message] = NavigationMsg
    elif isinstance(out, list) and (not out or isinstance(out[0], Detection)):
        cls = DetectionsMsg
    else:
        cls = ValueMsg
    return cls(robot=source.robot, sim_t=source.sim_t, data=out, meta=source.meta, trace=trace)


@dataclass(frozen=True)
class EncodedFrame:
    """A frame's pixels as JPEG bytes (the wire form across tiers; decoded once by the receiving actor)."""

    jpeg: bytes


@dataclass(eq=False)
class Delivery:
    """``msg`` for component ``cid`` of another actor, entering it at ``port``. ``cascade``: the sender's lock-step
    clock waits for everything derived from this message, so the receiver answers (the channel's done, the Ray
    call's return) only once its own cascade for it is done, whatever the transport; ``reply_to``: the sender's
    host id — outputs bound for the sender's components come back in the reply (a list of Delivery) instead of a
    call of their own."""

    cid: str
    port: Port
    msg: Message
    cascade: bool = False
    reply_to: str | None = None


@dataclass(frozen=True)
class RecordItem(ABC):
    """What an actor without the file sends the run's recorder actor (:class:`~aerodaas.actors.recording.remote_recorder.
    RemoteRecorder`); :meth:`apply` hands it to the :class:`~aerodaas.actors.recording.recorder.RecorderService`.

    The kinds counted on a :meth:`stream` (image, detections, odometry, JSON) end with ``seq``: its producer's
    sequence number on that stream
    (0, 1, 2 ... per producer actor and stream, counting every message offered, also those dropped before they
    reached the file; continued across the producer's restarts), written as the MCAP message's ``sequence``; -1
    until the producer numbered it."""

    @abstractmethod
    def apply(self, recorder: Any) -> None:
        """Hand this item to ``recorder`` (a RecorderService: non-blocking)."""

    def stream(self) -> str | None:
        """The topic this item's sequence number counts on (what the recording's accounting is per), or None
        for an item that is not counted (a camera's registration, a tracking analytics' tracks)."""
        return getattr(self, "topic", None)

    def numbered(self, seq: int) -> "RecordItem":
        """This item with sequence number ``seq``."""
        return dataclasses.replace(self, seq=seq) if hasattr(self, "seq") else self

    def of_incarnation(self, incarnation: int) -> "RecordItem":
        """This item sent by incarnation ``incarnation`` of its producer (the kinds the recorder's duplicate rule
        reads, a frame and an odometry sample, carry it; :attr:`ProducerLedger.incarnation`)."""
        return dataclasses.replace(self, incarnation=incarnation) if hasattr(self, "incarnation") else self


#: the keys of a drone's checkpoint that hold its waypoint queue (:func:`aerodaas.actors.drone.checkpoint.drone_checkpoint`),
#: sent apart from the rest when they changed (:class:`SealedCheckpoint`)
QUEUE_KEYS = ("missions", "completed", "segments_issued", "seq_missions", "preplanned_flags")


@dataclass(frozen=True)
class SealedCheckpoint:
    """A drone's checkpoint (:func:`aerodaas.actors.drone.checkpoint.drone_checkpoint`) as the recorder actor keeps it:
    ``robot``, its sequence number ``seq`` (newer is larger) and ``blob``, the state pickled by the drone actor's
    data-plane pool. The recorder never unpickles it: opening a checkpoint imports the classes in it (numpy, the
    pydantic waypoints, the mission queue) and, in a recorder that had not imported them yet, that stalled its writer
    thread for long enough to fill its frame queue, so frames were dropped and the run ended ``recording_lost``
    (tests/perception/test_fleet_follow.py, at the first checkpoint of the mission). The restarted drone actor and the
    driver open it (:meth:`open`).

    The waypoint queue (the :data:`QUEUE_KEYS` of the checkpoint: hundreds of pickled waypoints) travels apart, as
    ``queue_blob`` numbered ``queue_id`` (> 0), only when it changed otherwise than by flying: the state of every
    checkpoint names the queue it goes with (``queue_id``) and, under ``"queue_delta"``, what was flown since (the
    items taken off the head of each mission, the waypoints completed). The recorder keeps a robot's newest queue
    beside its newest state and gives them back together (:meth:`with_queue`); ``queue_id`` 0: the whole queue is
    in ``blob`` (a checkpoint of before, or one taken whole)."""

    robot: str
    seq: int
    blob: bytes
    queue_id: int = 0
    queue_blob: bytes | None = None

    @classmethod
    def seal(cls, state: dict, queue: dict | None = None, queue_id: int = 0) -> "SealedCheckpoint":
        """Pickle ``state`` (a checkpoint dict with ``robot`` and ``seq``) with Ray's cloudpickle; ``queue``: the
        queue it goes with (:data:`QUEUE_KEYS`), sent now, numbered ``queue_id``; None with a ``queue_id`` > 0: the
        recorder has that queue already."""
        from ray import cloudpickle  # lazy: heavy ray

        return cls(str(state["robot"]), int(state.get("seq", 0)), cloudpickle.dumps(state), int(queue_id),
                   None if queue is None else cloudpickle.dumps(queue))

    def with_queue(self, queue_id: int, queue_blob: bytes | None) -> "SealedCheckpoint":
        """This checkpoint with the queue ``queue_blob`` numbered ``queue_id`` (the recorder's, given back)."""
        return dataclasses.replace(self, queue_id=queue_id, queue_blob=queue_blob)

    def open(self) -> dict:
        """The checkpoint dict again, whole (imports the classes it holds). Raises ValueError when its state goes
        with a queue that is not here."""
        state = pickle.loads(self.blob)
        delta = state.pop("queue_delta", None)
        if not self.queue_id:
            return state
        if self.queue_blob is None or delta is None:
            raise ValueError(f"checkpoint {self.seq} of robot {self.robot!r}: its waypoint queue {self.queue_id} is "
                             f"missing")
        return {**state, **_flown(pickle.loads(self.queue_blob), delta)}


def _flown(queue: dict, delta: dict) -> dict:
    """The checkpoint's queue keys (:data:`QUEUE_KEYS`) of ``queue`` after ``delta``: ``{"missions": [[mission seq,
    items taken off its head], ...] (the missions still queued, in their order), "completed": [ids completed
    since]}``. A mission's items are never changed in place and its segment tags are keyed by its items, so taking
    items off the head is slicing its list."""
    by_seq = {m.seq: (m, flags) for m, flags in zip(queue["missions"], queue["preplanned_flags"])}
    missions, flags = [], []
    for seq, taken in delta["missions"]:
        m, f = by_seq[seq]
        m.items = m.items[taken:]
        missions.append(m)
        flags.append(f[taken:])
    return {**queue, "missions": missions, "preplanned_flags": flags,
            "completed": list(queue["completed"]) + list(delta["completed"])}


@dataclass(frozen=True)
class ProducerLedger:
    """What one producer actor (``producer``: its host id) had offered the recorder per stream (topic -> messages
    numbered so far, the frames it dropped itself included), sent with each of its batches; the recorder actor
    keeps the largest per producer and key, and gives it back to a restarted producer, whose counts go on from
    there (:class:`~aerodaas.actors.recording.remote_recorder.RemoteRecorder`).

    An analytics' recorded outputs are accounted against its inputs: ``offered_to`` counts the items this actor
    handed each analytics component (consumer component id -> robot -> items), ``no_output`` the items each of this
    actor's analytics took without recording an output (its own component id -> robot -> items: ``process``
    returned None or something unrecorded, raised, a stale item, a task the analytics scheduler did not run on
    time) and ``analytics`` names them (component id -> analytics name, the ``/<robot>/<name>`` of its topics).

    ``incarnation`` numbers the producer's processes: 1 for its first, one more for each restart (handed out by the
    recorder actor, ``RecorderActor.ledger_of``, never reused even when a batch of the dead process is still on
    its way); 0 for a ledger not from a producer process (the recorder's own, a test's). The recorder's duplicate
    rule is keyed by it (:class:`aerodaas.actors.recording.recorder.RecorderService`)."""

    producer: str
    produced: dict[str, int]
    offered_to: dict[str, dict[str, int]] = field(default_factory=dict)
    no_output: dict[str, dict[str, int]] = field(default_factory=dict)
    analytics: dict[str, str] = field(default_factory=dict)
    incarnation: int = 0

    def merged(self, other: "ProducerLedger") -> "ProducerLedger":
        """The largest count of each key of this ledger and ``other`` (batches may arrive out of order)."""
        def most(a: dict, b: dict) -> dict:
            return {k: max(a.get(k, 0), b.get(k, 0)) for k in {*a, *b}}

        def most2(a: dict, b: dict) -> dict:
            return {k: most(a.get(k, {}), b.get(k, {})) for k in {*a, *b}}

        return ProducerLedger(self.producer, most(self.produced, other.produced),
                              most2(self.offered_to, other.offered_to), most2(self.no_output, other.no_output),
                              {**self.analytics, **other.analytics}, max(self.incarnation, other.incarnation))

    def plus(self, produced: dict[str, int], offered_to: dict[str, dict[str, int]],
             no_output: dict[str, dict[str, int]], analytics: dict[str, str]) -> "ProducerLedger":
        """This ledger (an earlier incarnation's counts) with a later incarnation's counts added; its
        ``incarnation`` is this ledger's (the one :meth:`RecorderActor.ledger_of` gave the later process)."""
        def add(a: dict, b: dict) -> dict:
            return {k: a.get(k, 0) + b.get(k, 0) for k in {*a, *b}}

        def add2(a: dict, b: dict) -> dict:
            return {k: add(a.get(k, {}), b.get(k, {})) for k in {*a, *b}}

        return ProducerLedger(self.producer, add(self.produced, produced), add2(self.offered_to, offered_to),
                              add2(self.no_output, no_output), {**self.analytics, **analytics}, self.incarnation)


@dataclass(frozen=True)
class RecordImage(RecordItem):
    """A camera frame for ``topic`` at ``t_ns`` (log time, ns): ``frame`` is JPEG bytes on the wire (encoded by
    the sender) or the (H, W, 3) uint8 BGR ``ndarray`` before that; ``incarnation``: its producer's
    (:attr:`ProducerLedger.incarnation`)."""

    topic: str
    t_ns: int
    frame: Any
    frame_id: str
    seq: int = -1
    incarnation: int = 0

    def apply(self, recorder: Any) -> None:
        recorder.image(self.topic, self.t_ns, self.frame, self.frame_id, seq=self.seq, incarnation=self.incarnation)


@dataclass(frozen=True)
class RecordCamera(RecordItem):
    """A camera's intrinsics (pixels) and mount pitch (degrees) for the transform tree and calibration."""

    robot: str
    sensor: str
    intrinsics: dict
    pitch_deg: float

    def apply(self, recorder: Any) -> None:
        recorder.camera(self.robot, self.sensor, self.intrinsics, self.pitch_deg)


@dataclass(frozen=True)
class RecordDetections(RecordItem):
    """Detections for ``topic`` at ``t_ns``; ``image_size`` (W, H) pixels of the frame they were found in."""

    topic: str
    t_ns: int
    detections: list
    image_size: tuple[int, int] | None = None
    seq: int = -1

    def apply(self, recorder: Any) -> None:
        recorder.detections(self.topic, self.t_ns, self.detections, self.image_size, seq=self.seq)


@dataclass(frozen=True)
class RecordTracks(RecordItem):
    """One frame's geo-located tracks of drone ``robot`` under topic ``prefix`` at ``t_ns``: ``rows`` as
    :func:`aerodaas.perception.track_records.track_rows` makes them; ``image_size`` (W, H) pixels of the frame."""

    prefix: str
    t_ns: int
    robot: str
    rows: list
    image_size: tuple[int, int] | None = None

    def apply(self, recorder: Any) -> None:
        recorder.tracks(self.prefix, self.t_ns, self.robot, self.rows, self.image_size)

    def stream(self) -> str | None:
        return None  # several topics per frame, some only when there are tracks: not counted


@dataclass(frozen=True)
class RecordOdometry(RecordItem):
    """One odometry sample of ``robot`` (an Odometry dict) at ``t_ns``; ``incarnation``: its producer's
    (:attr:`ProducerLedger.incarnation`)."""

    robot: str
    t_ns: int
    odometry: dict
    seq: int = -1
    incarnation: int = 0

    def apply(self, recorder: Any) -> None:
        recorder.odometry(self.robot, self.t_ns, self.odometry, seq=self.seq, incarnation=self.incarnation)

    def stream(self) -> str | None:
        return f"/{self.robot}/odometry"


@dataclass(frozen=True)
class RecordJson(RecordItem):
    """A JSON message for ``topic`` at ``t_ns`` with the JSON Schema named ``schema_name``."""

    topic: str
    t_ns: int
    obj: dict
    schema_name: str
    seq: int = -1

    def apply(self, recorder: Any) -> None:
        recorder.json(self.topic, self.t_ns, self.obj, self.schema_name, seq=self.seq)
