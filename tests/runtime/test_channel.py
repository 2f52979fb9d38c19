"""Same-node channels (aerodaas.actors.data.channel) on their own: a server and an outlet in this process, talking over a
real abstract Unix socket and real POSIX shared memory."""
from __future__ import annotations

import gc
import os
import threading
import time

import numpy as np
import pytest

from aerodaas.actors.data.channel import ChannelServer, channel_address
from aerodaas.actors.data.channel_outlet import ChannelOutlet
from aerodaas.protocol.messages import Delivery, FrameMsg, NavigationMsg, Port, ValueMsg
from aerodaas.model.types import AeroNavigation, CameraIntrinsics, Detection, FrameMeta, FramePose

KEY = os.urandom(32)


def _wait(cond, timeout_s: float = 10.0) -> bool:
    """True as soon as ``cond()`` is (called until then, never once more), False after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.005)
    return False


class Receiver:
    """A stand-in for an actor's ``DataPlane.deliver``: remembers what arrived, answers with a reply for the sender,
    optionally keeps the frames or blocks until released."""

    def __init__(self, keep: bool = False) -> None:
        self.got: list = []
        self.kept: list = []
        self.keep = keep
        self.gate = threading.Event()
        self.gate.set()

    def __call__(self, d: Delivery) -> list:
        self.gate.wait(10)
        m = d.msg
        arr = m.data if isinstance(m, FrameMsg) else None
        self.got.append((d.cid, d.port, type(m).__name__, None if arr is None else (arr.shape, bool(arr.flags.writeable),
                                                                                     int(arr[0, 0, 0]), int(arr.sum() % 997))))
        if self.keep and arr is not None:
            self.kept.append(arr)
        nav = NavigationMsg(robot=m.robot, sim_t=m.sim_t, data=AeroNavigation(waypoints=[]), trace=dict(m.trace))
        return [Delivery("d1/scheduler", Port("priority", 1), nav)]


def _frame(value: int, shape=(720, 1280, 3)) -> FrameMsg:
    a = np.full(shape, value, np.uint8)
    a[0, 1, 2] = (value + 1) % 256
    a.flags.writeable = False
    return FrameMsg(robot="d1", sim_t=0.1 * value, data=a, trace={"capture_wall": time.time()})


def _meta(seq: int, shape: tuple[int, ...]) -> FrameMeta:
    """The metadata of frame ``seq`` of a ``shape`` (H, W, 3) camera hovering 10 m up, as a camera makes it."""
    h, w = shape[:2]
    return FrameMeta(robot_id="d1", sensor_id="cam", seq=seq, capture_time=0.1 * seq, wall_time=time.time(),
                     pose=FramePose(position=(0.0, 0.0, 10.0)),
                     intrinsics=CameraIntrinsics(width=w, height=h, fx=float(w), fy=float(w), cx=w / 2, cy=h / 2))


@pytest.fixture
def address(request):
    return channel_address(KEY, f"test/{request.node.name}/{os.getpid()}")


def test_frames_arrive_read_only_and_equal_and_replies_come_back(address):
    rx = Receiver()
    srv = ChannelServer(address, KEY, rx)
    replies: list = []
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=1, reply_to="drone/d1", on_reply=replies.extend)
    try:
        for v in (3, 7, 11):
            assert out.send(_frame(v)) is not None
            assert _wait(lambda: len(replies) == (3, 7, 11).index(v) + 1)
        out.send(ValueMsg(robot="d1", sim_t=1.0, data={"battery": 90}))
        assert _wait(lambda: len(rx.got) == 4)
        want = [(v, int(_frame(v).data.sum() % 997)) for v in (3, 7, 11)]
        assert [(g[3][2], g[3][3]) for g in rx.got[:3]] == want
        assert all(g[:3] == ("detector#1", Port("in"), "FrameMsg") and g[3][0] == (720, 1280, 3) and not g[3][1]
                   for g in rx.got[:3])
        assert rx.got[3][2] == "ValueMsg" and rx.got[3][3] is None
        assert all(d.cid == "d1/scheduler" and isinstance(d.msg, NavigationMsg) for d in replies)
        assert all("put_ms" in d.msg.trace and "get_ms" in d.msg.trace for d in replies[:3])
        st = out.stats()
        # one slot reused for every frame: the receiver let go of each before the next was sent
        assert st["sent"] == 4 and st["dropped"] == 0 and st["failed"] == 0 and st["slots"] == 1
    finally:
        out.close()
        srv.close()


def test_a_detection_reply_gets_back_the_very_frame_metadata_the_sender_sent(address):
    """The receiver's detections carry the frame's FrameMeta (as every analytics output does): the sender's
    component receives its own FrameMeta object back (the wire sent a marker, not the metadata), the detections and
    the trace equal to what the receiver made, the frame's pixels as sent."""
    from aerodaas.protocol.messages import DetectionsMsg

    seen: list = []

    def detect(d: Delivery) -> list:
        m = d.msg
        seen.append((type(m.meta).__name__, m.meta.seq, int(m.data[0, 1, 2])))
        box = Detection(class_id=2, class_name="car", score=0.9, box=(1.0, 2.0, 30.0, 20.0))
        return [Delivery("d1/follow", Port("in"), DetectionsMsg(robot=m.robot, sim_t=m.sim_t, data=[box],
                                                                  meta=m.meta, trace={**m.trace, "inference_ms": 4.0}))]

    srv = ChannelServer(address, KEY, detect)
    replies: list = []
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=1, reply_to="drone/d1", on_reply=replies.extend)
    try:
        frame = _frame(5, (48, 64, 3))
        frame.meta = _meta(41, (48, 64, 3))
        assert out.send(frame) is not None
        assert _wait(lambda: len(replies) == 1)
        (r,) = replies
        assert seen == [("FrameMeta", 41, 6)]
        assert r.cid == "d1/follow" and r.msg.meta is frame.meta
        assert r.msg.data == [Detection(class_id=2, class_name="car", score=0.9, box=(1.0, 2.0, 30.0, 20.0))]
        assert r.msg.trace["inference_ms"] == 4.0 and r.msg.trace["capture_wall"] == frame.trace["capture_wall"]
    finally:
        out.close()
        srv.close()


def test_in_flight_limit_drops_and_counts(address):
    rx = Receiver()
    rx.gate.clear()  # the receiver is busy with the first delivery
    srv = ChannelServer(address, KEY, rx)
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=1, reply_to=None, on_reply=lambda r: None)
    try:
        assert out.send(_frame(1, (48, 64, 3))) is not None
        assert out.send(_frame(2, (48, 64, 3))) is None and out.dropped == 1
        rx.gate.set()
        assert _wait(lambda: len(rx.got) == 1 and not out._in_flight)
        assert out.send(_frame(3, (48, 64, 3))) is not None
        assert _wait(lambda: len(rx.got) == 2)
    finally:
        out.close()
        srv.close()


def test_a_kept_frame_keeps_its_slot_until_it_is_collected(address):
    """An analytics that keeps frames keeps their slots (as an ObjectRef keeps its object): the sender never
    overwrites them; with every slot held the next frame travels in the message itself (never dropped); once the
    kept frames are collected their slots are written again."""
    rx = Receiver(keep=True)
    srv = ChannelServer(address, KEY, rx)
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=1, reply_to=None, on_reply=lambda r: None,
                        max_slots=3)
    try:
        for v in (1, 2, 3, 4):
            assert out.send(_frame(v, (48, 64, 3))) is not None
            assert _wait(lambda: not out._in_flight)
        assert out.inline_frames == 1 and out.stats()["slots"] == 3 and out.dropped == 0
        assert [int(a[0, 0, 0]) for a in rx.kept] == [1, 2, 3, 4]  # nothing was overwritten
        assert rx.got[3][3][3] == int(_frame(4, (48, 64, 3)).data.sum() % 997) and not rx.got[3][3][1]  # read-only
        rx.kept.clear()
        gc.collect()
        assert _wait(lambda: all(s.free for s in out._slots.values()))
        assert out.send(_frame(5, (48, 64, 3))) is not None
        assert _wait(lambda: len(rx.got) == 5) and rx.got[-1][3][2] == 5 and out.inline_frames == 1
    finally:
        out.close()
        srv.close()



def test_a_restarted_receiver_is_reconnected_and_in_flight_items_count_as_failed(address):
    rx = Receiver()
    rx.gate.clear()
    srv = ChannelServer(address, KEY, rx)
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=2, reply_to=None, on_reply=lambda r: None,
                        retry_s=0.05)
    try:
        assert out.send(_frame(1, (48, 64, 3))) is not None
        srv.close()  # the receiving actor dies with a delivery in flight
        rx.gate.set()
        assert _wait(lambda: out.failed >= 1 and not out.connected)
        rx2 = Receiver()
        srv = ChannelServer(address, KEY, rx2)  # restarted: the same address again
        assert _wait(lambda: out.send(_frame(2, (48, 64, 3))) is not None)
        assert _wait(lambda: len(rx2.got) == 1) and rx2.got[0][3][2] == 2 and out.reconnects >= 1
    finally:
        out.close()
        srv.close()


def test_a_server_closed_while_it_still_authenticates_a_sender_ends_that_connection_too(address, monkeypatch):
    """The sender's side of the handshake ends one message before the server's: a close() in that gap must still
    end the connection (CI once saw a delivery answered by a server closed before it), so the in-flight delivery
    counts as failed and a restarted server is reconnected to."""
    import aerodaas.actors.data.channel as channel

    real = channel.mpc.answer_challenge
    server_authenticating = threading.Event()
    closed = threading.Event()

    def slow_server_side(conn, key):  # the server's last handshake step, held open until the server was closed
        real(conn, key)
        if threading.current_thread().name == "aerodaas-channel-in":
            server_authenticating.set()
            closed.wait(10)

    monkeypatch.setattr(channel.mpc, "answer_challenge", slow_server_side)
    rx = Receiver()
    srv = ChannelServer(address, KEY, rx)
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=2, reply_to=None, on_reply=lambda r: None,
                        retry_s=0.05)
    try:
        assert out.send(_frame(1, (48, 64, 3))) is not None
        assert server_authenticating.wait(10)
        srv.close()
        closed.set()
        assert _wait(lambda: out.failed >= 1 and not out.connected)
        assert rx.got == []  # the closed server handed nothing on
        monkeypatch.setattr(channel.mpc, "answer_challenge", real)
        rx2 = Receiver()
        srv = ChannelServer(address, KEY, rx2)
        assert _wait(lambda: out.send(_frame(2, (48, 64, 3))) is not None)
        assert _wait(lambda: len(rx2.got) == 1) and rx2.got[0][3][2] == 2 and out.reconnects >= 1
    finally:
        out.close()
        srv.close()


def test_nobody_serving_or_a_wrong_key_is_refused(address):
    with pytest.raises(OSError):
        ChannelOutlet(address, KEY, "x", Port("in"), 1, None, lambda r: None)
    srv = ChannelServer(address, KEY, Receiver())
    try:
        from multiprocessing import AuthenticationError

        with pytest.raises((AuthenticationError, OSError, EOFError)):
            ChannelOutlet(address, os.urandom(32), "x", Port("in"), 1, None, lambda r: None)
    finally:
        srv.close()


def test_a_lockstep_delivery_holds_the_senders_cascade_until_the_receivers_cascade_is_done(address):
    """Lock-step over the channel (no Ray calls): a frame of a cascade is sent even beyond ``buffer`` (never
    dropped), the receiver answers only when its own cascade for it is done (here: when released), and the sender's
    cascade stays open until that answer arrived and its replies — which join the same cascade — were handed on,
    each with the very frame metadata object the sender sent (the answer, written later from another thread, refers
    to it)."""
    from aerodaas.actors.data.cascade import Cascade

    pending: list = []

    def deliver(d: Delivery, answer=None):
        assert d.cascade and answer is not None  # a lock-step delivery: answered later, the reader never blocks
        replies = Receiver()(d)
        for r in replies:
            r.msg.meta = d.msg.meta  # an output of this frame carries its metadata
        pending.append((answer, replies))
        return None

    srv = ChannelServer(address, KEY, deliver)
    handed: list = []
    holds: list = []

    def on_reply(items):  # the sender's components: each reply keeps the cascade open while it is processed
        for d in items:
            d.msg.tok.add()
            holds.append(d.msg.tok)
            handed.append(d)

    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=1, reply_to="drone/d1", on_reply=on_reply)
    try:
        tok = Cascade()
        metas = []
        for i in range(3):  # three frames of one cascade with buffer=1: none dropped
            f = _frame(i, shape=(8, 8, 3))
            f.tok = tok
            f.meta = _meta(i, (8, 8, 3))
            metas.append(f.meta)
            assert out.send(f) is not None
        assert _wait(lambda: len(pending) == 3)
        assert out.stats()["dropped"] == 0 and tok.outstanding == 3
        with pytest.raises(TimeoutError):
            tok.wait(0.2)  # the receiver's cascades are not done: simulated time must not move on
        for answer, replies in pending:
            answer(replies)
        assert _wait(lambda: len(handed) == 3)
        assert all(d.msg.tok is tok for d in handed) and tok.outstanding == 3  # the replies' own work holds it
        assert sorted((d.msg.meta.seq, id(d.msg.meta)) for d in handed) == [(i, id(m)) for i, m in enumerate(metas)]
        for t in holds:
            t.done()
        tok.wait(5)
        assert tok.outstanding == 0 and out.stats()["failed"] == 0
    finally:
        out.close()
        srv.close()


def test_a_lockstep_send_waits_for_the_restarted_receiver_and_gives_up_after_its_hold(address):
    """The receiving actor dies and Ray restarts it: a frame of a lock-step cascade waits for the new server (its
    cascade keeps the clock still) instead of failing; if nobody comes back within ``hold_s`` it fails, and later
    ones fail at once (no second wait) until the outlet reconnects."""
    from aerodaas.actors.data.cascade import Cascade

    srv = ChannelServer(address, KEY, Receiver())
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=1, reply_to=None, on_reply=lambda r: None,
                        retry_s=0.02, hold_s=30.0)
    sent: list = []
    try:
        srv.close()  # the receiver died
        assert _wait(lambda: out._conn is None)
        f = _frame(1, (8, 8, 3))
        f.tok = Cascade()
        t = threading.Thread(target=lambda: sent.append(out.send(f)))
        t.start()
        assert _wait(lambda: out.held == 1)  # waiting, not failed
        assert out.failed == 0 and not sent
        got: list = []

        def deliver(d: Delivery, answer=None):  # the restarted actor: answers the lock-step delivery at once
            got.append(d.msg.sim_t)
            answer([])
            return None

        srv = ChannelServer(address, KEY, deliver)  # restarted at the same address
        t.join(30)
        assert sent and sent[0] is not None and _wait(lambda: len(got) == 1) and _wait(lambda: not out.busy())
        assert out.failed == 0 and out.reconnects == 1 and not out.lost
        srv.close()
        assert _wait(lambda: out._conn is None)
        out.hold_s = 0.05  # nobody comes back this time
        g = _frame(2, (8, 8, 3))
        g.tok = Cascade()
        assert out.send(g) is None and out.lost and out.failed == 1
        h = _frame(3, (8, 8, 3))
        h.tok = Cascade()
        assert out.send(h) is None and out.held == 2 and out.failed == 2  # failed at once: no second wait
    finally:
        out.close()
        srv.close()


@pytest.mark.parametrize("inline, local_reader, on_pool", [(True, False, False), (False, False, True),
                                                          (True, True, True)])
def test_a_frame_for_a_channel_alone_leaves_in_the_publishing_thread(address, inline, local_reader, on_pool):
    """A frame whose only reader is another actor's component on a same-node channel is copied and sent by the
    thread that publishes it (no pool hop per frame); a publisher that must not wait (``inline``
    False, the clock's) or a local reader behind it leaves the send to the pool. Observed with the pool's every
    thread held: a send made in this thread has reached the receiver before the pool is free again."""
    from aerodaas.actors.data.plane import Component, DataPlane

    rx = Receiver()
    peer = "analytics/edge/det#1"
    addr = channel_address(KEY, peer)
    srv = ChannelServer(addr, KEY, rx)
    plane = DataPlane("drone/d1", "edge", 0, workers=2)
    plane.channel_key = KEY
    routes = [("det", Port("in"), 1, None)]
    if local_reader:
        plane.add(Component(plane, "rec"))
        routes.append(("rec", Port("in"), 1, None))
    plane.connect({"cam": routes}, {"det": peer}, {peer: "edge"}, {peer: "aerodaas/run/analytics/det"})
    hold = threading.Event()
    started = threading.Semaphore(0)

    def occupy() -> None:
        started.release()
        hold.wait(30)

    try:
        for _ in range(plane.workers):
            plane.submit(occupy)
        for _ in range(plane.workers):
            assert started.acquire(timeout=30)  # every pool thread is held from here
        plane.publish("cam", [_frame(5)], None, inline=inline)
        if on_pool:
            time.sleep(0.2)  # were it sent here, it would have arrived by now
            assert rx.got == []
            hold.set()
        assert _wait(lambda: len(rx.got) == 1)
        assert rx.got[0][:3] == ("det", Port("in"), "FrameMsg") and rx.got[0][3][2] == 5
        assert not hold.is_set() if not on_pool else True
    finally:
        hold.set()
        plane.close()
        srv.close()


def test_a_frame_released_in_its_delivery_comes_back_in_the_answer_not_in_a_late_free(address):
    """A receiver that lets go of each frame while handling it frees the slot on the connection's own thread: the
    answer carries it, so one slot serves every frame and the outlet counts no late free. A kept frame, released
    later in another thread, comes back as one late free (``stats()["late_frees"]``). Whether a thread is woken for
    the first kind is the next test's (a late free also arrives by the 0.5 s poll)."""
    rx = Receiver()
    srv = ChannelServer(address, KEY, rx)
    replies: list = []
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=1, reply_to="drone/d1", on_reply=replies.extend)
    try:
        for n, v in enumerate(range(1, 21), start=1):
            assert out.send(_frame(v)) is not None
            assert _wait(lambda: len(replies) == n)
        st = out.stats()
        assert st["slots"] == 1 and st["inline_frames"] == 0 and st["late_frees"] == 0, st
        rx.keep = True
        assert out.send(_frame(99)) is not None
        assert _wait(lambda: len(replies) == 21)
        rx.kept.clear()  # let go of here, in this test's thread: not the connection's
        gc.collect()
        assert _wait(lambda: out.stats()["late_frees"] == 1), out.stats()
    finally:
        out.close()
        srv.close()


def test_a_frame_freed_on_the_connections_thread_wakes_no_other_thread():
    """The finalizer of a mapped frame (``_freed``) only queues the slot when it runs on the connection's own thread,
    whose next answer carries it; run anywhere else it wakes the late-frees thread, which would otherwise tell the
    sender only at its next 0.5 s poll."""
    from collections import deque

    from aerodaas.actors.data.channel import _freed

    freed, wake = deque(), threading.Event()
    _freed(freed, wake, "slot-a", threading.get_ident(), None)
    assert list(freed) == ["slot-a"] and not wake.is_set()
    other = threading.Thread(target=_freed, args=(freed, wake, "slot-b", threading.get_ident(), None))
    other.start()
    other.join()
    assert list(freed) == ["slot-a", "slot-b"] and wake.is_set()
