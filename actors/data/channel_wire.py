"""The same-node channel's wire format (:mod:`aerodaas.actors.data.channel`): what a frame's delivery and its answer
look like on the Unix socket.

Why: a frame's delivery crosses the channel 30 times a second per consumer, and between two frames both actors
sleep, so the interpreter meets each message with cold caches and every Python-level step counts. Pickled as
objects (the :class:`ChannelSend` dataclass, its :class:`~aerodaas.protocol.messages.Delivery`, the ``FrameMsg`` and
the pydantic ``FrameMeta`` with its pose and intrinsics, whose pickling runs in Python), the delivery took 0.52-0.54 ms
from ``send`` to the receiving component and the answer 0.52-0.53 ms back, on this machine kind at 720p and 30 FPS;
as below, 0.38-0.49 and 0.32-0.45 ms (``docs/results/overhead.md``, "The actors layout, run by run"). So the common
messages travel as tuples of built-ins, which pickle encodes and decodes in C:

* a frame's delivery (:func:`encode_send`): a ``FrameMsg`` whose pixels are in a slot, its ``FrameMeta`` flattened
  (:func:`flatten`), the port and the trace as they are;
* an answer (:func:`encode_done`): each reply's kind and fields, its detections flattened, and its ``meta`` as the
  marker :data:`SAME_META` when it is the very ``FrameMeta`` object of the frame it answers (what
  :func:`~aerodaas.protocol.messages.output_message` gives every output): the sender puts back the object it sent
  (:func:`decode_done`), so the frame's metadata is not sent back at all, and the sender's components get the
  very object it sent (as a component of its own actor would; a receiver that changed it in place before
  replying would not see that change travel, and nothing here does).

Anything else (a frame sent inline, a message of another kind or class, a user's own metadata class or payload, a
model or message with attributes beyond its fields) travels pickled on its own inside the tuple: a delivery as
``(OBJECT, seq, bytes)``, an answer's replies as bytes. The tuple itself is built-ins only and always decodes, so a
class the other side cannot import fails that one message (answered, or counted, as failed), never the channel.
Decoding gives objects equal to what was encoded, with the same fields set (the pydantic models are rebuilt with
``model_construct``: their values were validated when they were made).
"""
from __future__ import annotations

import dataclasses
import functools
import pickle
from typing import Any

from aerodaas.actors.data.channel_msgs import ChannelDone, ChannelSend, SlotFrame, SlotFree
from aerodaas.model.types import CameraIntrinsics, Detection, FrameMeta, FramePose
from aerodaas.protocol.ids import ComponentId
from aerodaas.protocol.messages import (DetectionsMsg, Delivery, FrameMsg, Message, NavigationMsg, OdometryMsg, Port,
                                        StatMsg, ValueMsg)

__all__ = ["SAME_META", "OBJECT", "flatten", "unflatten", "encode_send", "encode_done", "encode_free", "decode",
           "decode_done"]

#: tags of the wire tuples
FRAME, DONE, FREE, OBJECT = "f", "d", "x", "o"
#: a reply's ``meta`` is the very FrameMeta of the frame its delivery carried
SAME_META = "="

#: the pydantic models flattened on the wire (a field typed as one of them is flattened too)
MODELS: tuple[type, ...] = (FrameMeta, FramePose, CameraIntrinsics, Detection)
_INDEX = {cls: i for i, cls in enumerate(MODELS)}
_FIELDS = [tuple(cls.model_fields) for cls in MODELS]
#: per model, the positions of its fields typed as another model of :data:`MODELS`
_NESTED = [frozenset(j for j, f in enumerate(cls.model_fields.values()) if f.annotation in _INDEX) for cls in MODELS]
#: the message kinds a reply's tuple names by position
KINDS: tuple[type[Message], ...] = (DetectionsMsg, NavigationMsg, ValueMsg, OdometryMsg, StatMsg, FrameMsg)
_KIND = {cls: i for i, cls in enumerate(KINDS)}
#: per kind, how many attributes an instance has (its dataclass fields): one with more travels as the object
_NATTR = tuple(len(dataclasses.fields(cls)) for cls in KINDS)


def flatten(m: Any) -> tuple:
    """Model ``m`` (an instance of exactly one of :data:`MODELS`) as ``(model index, fields set or None, field
    values...)`` in its fields' order, a field typed as another of :data:`MODELS` flattened likewise; the names
    of the fields set explicitly travel only when some were not (pydantic's ``model_fields_set``). Raises
    TypeError for anything else (the caller then sends the object pickled)."""
    i = _INDEX[type(m)] if type(m) in _INDEX else None
    if i is None:
        raise TypeError(f"not flattened on the wire: {type(m).__name__}")
    vals = list(m.__dict__.values())
    if len(vals) != len(_FIELDS[i]) or m.__pydantic_extra__ or m.__pydantic_private__:
        raise TypeError(f"{type(m).__name__} with attributes beyond its fields")
    for j in _NESTED[i]:
        if vals[j] is not None:
            vals[j] = flatten(vals[j])
    fs = m.__pydantic_fields_set__
    return (i, None if len(fs) == len(vals) else tuple(sorted(fs)), *vals)


def _plain(cls: type) -> bool:
    """True when ``cls.model_construct`` with every field given does nothing but set the instance's ``__dict__``,
    fields set, and empty extra and private attributes (no ``model_post_init``, no private attributes, no extra
    fields allowed, not a root model): :func:`unflatten` then sets those itself."""
    return (not cls.__pydantic_post_init__ and not cls.__private_attributes__ and not cls.__pydantic_root_model__
            and cls.model_config.get("extra") != "allow")


#: per model, whether :func:`unflatten` may build it without ``model_construct`` (see :func:`_plain`)
_PLAIN = tuple(_plain(cls) for cls in MODELS)
_ALL_SET = [frozenset(f) for f in _FIELDS]
_setattr = object.__setattr__


def unflatten(t: tuple) -> Any:
    """The model :func:`flatten` gave ``t`` for (equal to it, with the same fields set). Built as pydantic's
    ``model_construct`` builds it from every field's value (values validated when the model was made), without
    its per-field lookup of aliases and defaults: every field travels."""
    i, fs = t[0], t[1]
    names = _FIELDS[i]
    kw = dict(zip(names, t[2:]))
    for j in _NESTED[i]:
        v = t[2 + j]
        if v is not None:
            kw[names[j]] = unflatten(v)
    cls = MODELS[i]
    if not _PLAIN[i] or len(kw) != len(names):
        return cls.model_construct(None if fs is None else set(fs), **kw)
    m = cls.__new__(cls)
    _setattr(m, "__dict__", kw)
    _setattr(m, "__pydantic_fields_set__", set(_ALL_SET[i] if fs is None else fs))
    _setattr(m, "__pydantic_extra__", None)
    _setattr(m, "__pydantic_private__", None)
    return m


def _cid(c: Any) -> Any:
    """Component id ``c`` on the wire: a :class:`~aerodaas.protocol.ids.ComponentId` whose kind and robot are
    strings (or no robot) as the tuple ``(id, kind, robot)`` (pickled in C, where the object's own ``__reduce__``
    runs in Python on both ends); anything else as it is."""
    if type(c) is ComponentId and type(c.kind) is str and (c.robot is None or type(c.robot) is str):
        return (str(c), c.kind, c.robot)
    return c


def _uncid(w: Any) -> Any:
    """The component id :func:`_cid` gave ``w`` for (an equal ComponentId, the same object for the same tuple)."""
    return _component_id(*w) if type(w) is tuple else w


@functools.lru_cache(maxsize=1024)
def _component_id(value: str, kind: Any, robot: Any) -> ComponentId:
    """One ComponentId per wire tuple (a run has a handful of components; the memo spares a construction per
    message)."""
    return ComponentId(value, kind, robot)


@functools.lru_cache(maxsize=1024)
def _unport(name: Any, priority: Any, replace: Any) -> Port:
    """The :class:`~aerodaas.protocol.messages.Port` whose wire tuple :func:`_port` gave (frozen: one object serves
    every message of an edge)."""
    return Port(name, priority, replace)


def _port(p: Port) -> tuple:
    return (p.name, p.priority, p.replace)


def _pickled(obj: Any) -> bytes:
    """``obj`` pickled on its own (the receiver unpickles it inside its error handling: a class it cannot import
    fails that message only, never the connection's envelope). Raises what pickling raises."""
    return pickle.dumps(obj, pickle.HIGHEST_PROTOCOL)


def encode_send(send: ChannelSend) -> tuple:
    """``send`` as the tuple that travels: a frame in a slot with FrameMeta (or no) metadata flattened, anything
    else as ``(OBJECT, seq, pickled send)``. Raises what pickling ``send`` raises."""
    d, m = send.delivery, send.delivery.msg
    if (type(m) is FrameMsg and type(m.data) is SlotFrame and m.ref is None and m.jpeg is None
            and (m.meta is None or type(m.meta) is FrameMeta)):
        try:
            meta = None if m.meta is None else flatten(m.meta)
        except TypeError:
            return (OBJECT, send.seq, _pickled(send))
        s = m.data
        return (FRAME, send.seq, _cid(d.cid), _port(d.port), d.cascade, d.reply_to, m.robot, m.sim_t,
                (s.name, s.shape, s.dtype), m.trace, meta)
    return (OBJECT, send.seq, _pickled(send))


def _reply(d: Delivery, meta: Any) -> tuple:
    """One reply item: ``(cid, port, kind index, robot, sim_t, data, meta, trace)``, its detections flattened
    (``data`` then ``("D", [...])``, else ``("o", pickled data)``) and its meta :data:`SAME_META` when it is
    ``meta`` (else None or ``("o", pickled meta)``)."""
    m = d.msg
    k = _KIND.get(type(m))
    if (k is None or type(d) is not Delivery or d.cascade or d.reply_to is not None or m.tok is not None
            or len(m.__dict__) != _NATTR[k] or (type(m) is FrameMsg and (m.ref is not None or m.jpeg is not None))):
        raise TypeError(type(m).__name__)
    if type(m) is DetectionsMsg and type(m.data) is list and all(type(x) is Detection for x in m.data):
        data: tuple = ("D", [flatten(x) for x in m.data])
    else:
        data = ("o", _pickled(m.data))
    if m.meta is None:
        mt: Any = None
    elif meta is not None and m.meta is meta:
        mt = SAME_META
    else:
        mt = ("o", _pickled(m.meta))
    return (_cid(d.cid), _port(d.port), k, m.robot, m.sim_t, data, mt, m.trace)


def encode_done(done: ChannelDone, meta: Any = None) -> tuple:
    """``done`` as the tuple that travels; ``meta``: the FrameMeta object of the frame the answered delivery
    carried (a reply whose ``meta`` is that very object travels as :data:`SAME_META`; anything but a FrameMeta is
    ignored here). Anything that is not a plain message (another Delivery class, a reply with ``cascade`` or
    ``reply_to`` set, a message class or instance attribute the tuple does not carry) has its reply list pickled
    as a whole (bytes in the tuple). The tuple itself always decodes: replies that cannot be pickled here travel as
    none, with the reason as the answer's ``error`` (the delivery then counts as failed at the sender)."""
    if type(meta) is not FrameMeta:
        meta = None
    error = done.error
    try:
        try:
            replies: Any = [_reply(d, meta) for d in done.replies]
        except TypeError:
            replies = _pickled(done.replies)
    except Exception as e:  # noqa: BLE001 - an output this process cannot pickle: the answer says so
        replies, error = [], f"replies not sent: {type(e).__name__}: {e}"
    return (DONE, done.seq, replies, error, done.freed)


def encode_free(free: SlotFree) -> tuple:
    """A :class:`SlotFree` as the tuple that travels."""
    return (FREE, free.names)


def decode(t: tuple) -> Any:
    """What :func:`encode_send`, :func:`encode_done` or :func:`encode_free` encoded, as objects: a
    :class:`ChannelSend`, a :class:`ChannelDone` (a reply's :data:`SAME_META` left in place for
    :func:`decode_done`) or a :class:`SlotFree`. Raises ValueError for a tuple of no known tag."""
    tag = t[0]
    if tag == FRAME:
        _, seq, cid, port, cascade, reply_to, robot, sim_t, (name, shape, dtype), trace, meta = t
        msg = FrameMsg(robot, sim_t, SlotFrame(name, tuple(shape), dtype), None if meta is None else unflatten(meta),
                       trace)
        return ChannelSend(seq, Delivery(_uncid(cid), _unport(*port), msg, cascade, reply_to))
    if tag == DONE:
        return ChannelDone(t[1], t[2], t[3], tuple(t[4]))
    if tag == FREE:
        return SlotFree(tuple(t[1]))
    if tag == OBJECT:
        return pickle.loads(t[2])
    raise ValueError(f"channel: a message of no known tag {tag!r}")


def decode_done(replies: list, meta: Any) -> list[Delivery]:
    """The reply items of a :data:`DONE` tuple (pickled as a whole when they could not be flattened) as Delivery
    objects; ``meta``: the FrameMeta the answered delivery carried (put back where a
    reply says :data:`SAME_META`: the sender's components then get the very object it sent, as a component of its
    own actor would). Raises ValueError for a reply that says :data:`SAME_META` when ``meta`` is None (an answer
    to a delivery this sender no longer has in flight), and what unpickling a reply raises (e.g. a class this
    process cannot import)."""
    if isinstance(replies, bytes):
        return pickle.loads(replies)
    out = []
    for r in replies:
        cid, port, k, robot, sim_t, (dk, data), mt, trace = r
        data = [unflatten(x) for x in data] if dk == "D" else pickle.loads(data)
        if mt == SAME_META and meta is None:
            raise ValueError("channel: an answer refers to the metadata of a delivery no longer in flight")
        m = meta if mt == SAME_META else (None if mt is None else pickle.loads(mt[1]))
        out.append(Delivery(_uncid(cid), _unport(*port), KINDS[k](robot, sim_t, data, m, trace)))
    return out
