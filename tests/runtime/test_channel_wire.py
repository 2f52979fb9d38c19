"""The same-node channel's wire format (aerodaas.actors.data.channel_wire): a frame's delivery and its answer travel as
tuples of built-in values, decode to objects equal to what was sent, and a reply's metadata that is the frame's own
is not sent back; anything else travels as the objects themselves."""
from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aerodaas.actors.data.channel_msgs import ChannelDone, ChannelSend, SlotFrame, SlotFree
from aerodaas.actors.data.channel_wire import (OBJECT, SAME_META, decode, decode_done, encode_done, encode_free,
                                          encode_send, flatten)
from aerodaas.model.types import AeroNavigation, CameraIntrinsics, Detection, FrameMeta, FramePose
from aerodaas.protocol.messages import DetectionsMsg, Delivery, FrameMsg, NavigationMsg, Port, ValueMsg

BUILTIN = (int, float, str, bool, type(None))


class MyMeta(FrameMeta):
    """A user's own metadata class."""


class MyDetections(DetectionsMsg):
    """A user's own message class."""


def only_builtins(x) -> bool:
    """True when ``x`` is made of built-in scalars, tuples, lists and str-keyed dicts only (no object of ours)."""
    if isinstance(x, BUILTIN):
        return type(x) in BUILTIN
    if type(x) in (tuple, list):
        return all(only_builtins(v) for v in x)
    if type(x) is dict:
        return all(type(k) is str and only_builtins(v) for k, v in x.items())
    return False


def meta(seq: int = 7, arrival: float | None = None) -> FrameMeta:
    return FrameMeta(robot_id="d1", sensor_id="cam", seq=seq, capture_time=1.5, wall_time=1.8e9,
                     pose=FramePose(position=(1.0, -2.0, 16.0), yaw=33.0, camera_pitch=60.0),
                     intrinsics=CameraIntrinsics(width=1280, height=720, fx=900.0, fy=901.0, cx=640.0, cy=360.0),
                     arrival_time=arrival, pose_time=None if arrival is None else arrival - 0.01)


def frame_send(m: FrameMeta | None, seq: int = 3, cascade: bool = False, port: Port = Port("in")) -> ChannelSend:
    msg = FrameMsg(robot="d1", sim_t=1.5, data=SlotFrame("adc1_ab", (720, 1280, 3), "|u1"), meta=m,
                   trace={"capture_wall": 1.8e9, "put_ms": 0.3, "sent_wall": 1.8e9 + 0.001})
    return ChannelSend(seq, Delivery("detector#1", port, msg, cascade=cascade, reply_to="drone/d1"))


def fields_set(m) -> object:
    """The fields set explicitly of a model and of the models in it (pydantic's ``model_fields_set``)."""
    if m is None or not hasattr(m, "model_fields_set"):
        return None
    return (sorted(m.model_fields_set), [fields_set(getattr(m, f)) for f in type(m).model_fields])


def same_send(a: ChannelSend, b: ChannelSend) -> bool:
    da, db = a.delivery, b.delivery
    ma, mb = da.msg, db.msg
    return (a.seq == b.seq and (da.cid, da.port, da.cascade, da.reply_to) == (db.cid, db.port, db.cascade, db.reply_to)
            and type(ma) is type(mb)
            and (ma.robot, ma.sim_t, ma.meta, ma.trace) == (mb.robot, mb.sim_t, mb.meta, mb.trace)
            and fields_set(ma.meta) == fields_set(mb.meta)
            and (np.array_equal(ma.data, mb.data) if isinstance(ma.data, np.ndarray) else ma.data == mb.data))


def sparse_meta() -> FrameMeta:
    """Metadata whose pose sets only its position (yaw and pitch left to their defaults)."""
    return FrameMeta(robot_id="d1", sensor_id="cam", seq=1, capture_time=0.0, wall_time=0.0,
                     pose=FramePose(position=(0.0, 0.0, 5.0)),
                     intrinsics=CameraIntrinsics(width=64, height=48, fx=50.0, fy=50.0, cx=32.0, cy=24.0))


@pytest.mark.parametrize("m,port", [(meta(), Port("in")), (meta(arrival=1.49), Port("priority", 2, True)),
                                    (None, Port("in")), (sparse_meta(), Port("priority", 0))],
                         ids=["rendered", "streamed-to-a-replacing-priority", "no-meta", "fields-left-unset"])
def test_a_frames_delivery_travels_as_builtins_and_decodes_equal(m, port):
    send = frame_send(m, cascade=m is None, port=port)
    wire = encode_send(send)
    assert wire[0] != OBJECT and only_builtins(wire), wire
    back = decode(pickle.loads(pickle.dumps(wire, 5)))
    assert same_send(back, send)
    assert back.delivery.msg.meta is None if m is None else type(back.delivery.msg.meta) is FrameMeta


def test_a_reply_carrying_the_frames_own_meta_does_not_send_it_back():
    m = meta()
    det = DetectionsMsg(robot="d1", sim_t=1.5, meta=m, trace={"inference_ms": 9.8},
                        data=[Detection(class_id=2, class_name="car", score=0.81, box=(10.0, 20.0, 50.0, 44.0)),
                              Detection(class_id=0, class_name="person", score=0.5, box=(1.0, 2.0, 3.0, 4.0))])
    other = NavigationMsg(robot="d1", sim_t=1.5, meta=meta(seq=8), data=AeroNavigation(waypoints=[]), trace={})
    done = ChannelDone(3, [Delivery("d1/follow", Port("in"), det),
                           Delivery("d1/scheduler", Port("priority", 1, True), other)], None, ("adc1_ab",))
    wire = encode_done(done, m)
    assert wire[0] != OBJECT
    det_wire, nav_wire = wire[2]
    assert det_wire[6] == SAME_META and only_builtins(det_wire), det_wire     # neither the meta nor a Detection object
    assert nav_wire[6] != SAME_META                                          # another meta travels itself
    back = decode(pickle.loads(pickle.dumps(wire, 5)))
    assert isinstance(back, ChannelDone) and back.seq == 3 and back.freed == ("adc1_ab",) and back.error is None
    sent_meta = meta()  # the sender's own object (equal to m, not the same one): the reply gets exactly it
    r_det, r_nav = decode_done(back.replies, sent_meta)
    assert r_det.msg.meta is sent_meta
    assert (r_det.cid, r_det.port, type(r_det.msg), r_det.msg.data, r_det.msg.trace) == \
        ("d1/follow", Port("in"), DetectionsMsg, det.data, det.trace)
    assert (r_nav.cid, r_nav.port, type(r_nav.msg), r_nav.msg.meta, r_nav.msg.data) == \
        ("d1/scheduler", Port("priority", 1, True), NavigationMsg, other.meta, other.data)
    with pytest.raises(ValueError, match="no longer in flight"):  # the sender has no object to put back
        decode_done(back.replies, None)


def test_what_the_tuples_do_not_cover_travels_as_the_objects():
    pix = np.zeros((4, 6, 3), np.uint8)
    inline = ChannelSend(4, Delivery("detector#1", Port("in"), FrameMsg(robot="d1", sim_t=0.0, data=pix)))
    value = ChannelSend(5, Delivery("monitor#1", Port("in"), ValueMsg(robot="d1", sim_t=0.0, data={"battery": 90})))

    theirs = frame_send(MyMeta(**meta().model_dump()))
    extra = meta()
    extra.__dict__["note"] = "an attribute beyond the fields"
    for send in (inline, value, theirs, frame_send(extra)):
        wire = encode_send(send)
        assert wire[0] == OBJECT and wire[1] == send.seq and only_builtins(wire[:2]) and type(wire[2]) is bytes
        assert same_send(decode(pickle.loads(pickle.dumps(wire, 5))), send)

    m = meta()
    noted = DetectionsMsg(robot="d1", sim_t=0.0, data=[], meta=m)
    noted.note = "an attribute beyond the message's fields"
    for reply in (Delivery("d1/follow", Port("in"), MyDetections(robot="d1", sim_t=0.0, data=[], meta=m)),
                  Delivery("d1/follow", Port("in"), DetectionsMsg(robot="d1", sim_t=0.0, data=[], meta=m),
                           reply_to="drone/d2"),
                  Delivery("d1/follow", Port("in"), DetectionsMsg(robot="d1", sim_t=0.0, data=[], meta=m),
                           cascade=True),
                  Delivery("d1/follow", Port("in"), noted)):
        wire = encode_done(ChannelDone(7, [reply]), m)
        assert wire[0] != OBJECT and type(wire[2]) is bytes  # the replies pickled as a whole, the envelope not
        (r,) = decode_done(decode(pickle.loads(pickle.dumps(wire, 5))).replies, m)
        assert type(r.msg) is type(reply.msg) and (r.reply_to, r.cascade) == (reply.reply_to, reply.cascade)
        assert r.msg.meta == m and vars(r.msg).get("note") == vars(reply.msg).get("note")
    # only a FrameMeta is left behind: a delivery's other metadata (a dict here) travels back itself
    d_meta = {"source": "gas"}
    wire = encode_done(ChannelDone(8, [Delivery("x", Port("in"), ValueMsg(robot="d1", sim_t=0.0, data=1,
                                                                          meta=d_meta))]), d_meta)
    assert wire[2][0][6] != SAME_META and decode_done(wire[2], None)[0].msg.meta == d_meta
    # a reply this process cannot pickle: the answer still travels, with no replies and the reason as its error
    bad = ChannelDone(9, [Delivery("x", Port("in"), ValueMsg(robot="d1", sim_t=0.0, data=lambda: 1))])
    wire = encode_done(bad, None)
    assert only_builtins(wire) and wire[1] == 9 and wire[2] == [] and "replies not sent" in wire[3]
    odd = ChannelDone(6, [Delivery("d1/follow", Port("in"), DetectionsMsg(robot="d1", sim_t=0.0, data=["not a box"]))])
    wire = encode_done(odd, None)
    assert wire[0] != OBJECT and decode_done(decode(wire).replies, None)[0].msg.data == ["not a box"]
    assert decode(encode_free(SlotFree(("a", "b")))) == SlotFree(("a", "b"))
    with pytest.raises(ValueError, match="no known tag"):
        decode(("?", 1))
    with pytest.raises(TypeError):
        flatten(AeroNavigation(waypoints=[]))


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=60, deadline=None)
@given(seq=st.integers(0, 2**40), t=finite, pos=st.tuples(finite, finite, finite), yaw=finite,
       pitch=st.floats(0, 90), w=st.integers(1, 8000), h=st.integers(1, 8000), f=st.floats(1e-3, 1e5),
       arrival=st.none() | finite, score=st.floats(0, 1), name=st.text(max_size=12),
       trace=st.dictionaries(st.text(max_size=8), finite, max_size=6))
def test_any_valid_frame_and_detection_round_trips(seq, t, pos, yaw, pitch, w, h, f, arrival, score, name, trace):
    m = FrameMeta(robot_id=name, sensor_id="cam", seq=seq, capture_time=t, wall_time=t, arrival_time=arrival,
                  pose=FramePose(position=pos, yaw=yaw, camera_pitch=pitch),
                  intrinsics=CameraIntrinsics(width=w, height=h, fx=f, fy=f, cx=w / 2, cy=h / 2))
    send = frame_send(m, seq=seq)
    send.delivery.msg.trace.update(trace)
    assert same_send(decode(pickle.loads(pickle.dumps(encode_send(send), 5))), send)
    det = Detection(class_id=seq % 80, class_name=name, score=score, box=(pos[0], pos[1], pos[0] + 1, pos[1] + 1))
    done = ChannelDone(seq, [Delivery("x", Port("in"), DetectionsMsg(robot=name, sim_t=t, data=[det], meta=m))])
    (r,) = decode_done(decode(pickle.loads(pickle.dumps(encode_done(done, None), 5))).replies, None)
    assert r.msg.data == [det] and r.msg.meta == m


def test_typed_component_ids_travel_as_builtins_and_come_back_typed():
    """A delivery to a typed component id (the plan's ids) and a reply to one: the tuples stay built-ins, the
    decoded ids are ComponentIds with the same kind and robot."""
    from aerodaas.protocol.ids import ComponentId

    det_id, follow_id = ComponentId("detector#1", "analytics"), ComponentId("follow#2@d1", "analytics", "d1")
    send = frame_send(meta())
    send = ChannelSend(send.seq, Delivery(det_id, Port("in"), send.delivery.msg, reply_to="drone/d1"))
    wire = encode_send(send)
    assert only_builtins(wire), wire
    back = decode(pickle.loads(pickle.dumps(wire, 5))).delivery.cid
    assert (type(back), back, back.kind, back.robot) == (ComponentId, "detector#1", "analytics", None)
    det = DetectionsMsg(robot="d1", sim_t=1.5, meta=None, trace={}, data=[])
    wire = encode_done(ChannelDone(4, [Delivery(follow_id, Port("priority", 1), det)]))
    assert only_builtins(wire[2]), wire
    (r,) = decode_done(decode(pickle.loads(pickle.dumps(wire, 5))).replies, None)
    assert (type(r.cid), r.cid, r.cid.kind, r.cid.robot, r.port) == (ComponentId, "follow#2@d1", "analytics", "d1",
                                                                   Port("priority", 1))
