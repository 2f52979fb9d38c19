"""Same-node channels (aerodaas.actors.data.channel) on their own, what outlives what: a frame made in a slot the outlet
lends, mappings that must outlive every frame read from them, and messages or answers one side cannot take. The
helpers and the ``address`` fixture are test_channel.py's."""
from __future__ import annotations

import gc
import subprocess
import sys
import threading
import time
from multiprocessing import connection as mpc

from aerodaas.actors.data.channel import ChannelServer
from aerodaas.actors.data.channel_msgs import ChannelDone
from aerodaas.actors.data.channel_outlet import ChannelOutlet
from aerodaas.actors.data.channel_wire import decode, encode_done
from aerodaas.actors.data.frames import FrameCopies
from aerodaas.model.types import AeroNavigation
from aerodaas.protocol.messages import Delivery, FrameMsg, NavigationMsg, Port, ValueMsg
from tests.runtime.test_channel import KEY, Receiver, _frame, _meta, _wait, address  # noqa: F401 - address: fixture


def test_a_frame_made_in_a_lent_slot_is_sent_without_a_copy_and_its_slot_waits_for_both_sides(address):
    """A camera that renders into a slot the outlet lends: the frame crosses with no copy (``in_place``, the
    ``channel_in_place`` counter, not ``channel_copy``), the receiver reads exactly its pixels, and the slot is
    lent or written again only once the receiver let go of the frame *and* nothing here references it any more.
    Frames made here that stay referenced never take the last two slots: frames made elsewhere are still copied
    into a slot, never sent in their message."""
    rx = Receiver(keep=True)
    srv = ChannelServer(address, KEY, rx)
    copies = FrameCopies()
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=1, reply_to=None, on_reply=lambda r: None,
                        copies=copies, max_slots=4)

    def made(value: int) -> FrameMsg | None:
        buf = out.lend((48, 64, 3))
        if buf is None:
            return None
        assert buf.flags.writeable
        buf[:] = value
        buf[0, 1, 2] = value + 1
        buf.flags.writeable = False
        return FrameMsg(robot="d1", sim_t=0.1 * value, data=buf, trace={"capture_wall": time.time()})

    try:
        first = made(9)
        slot_of_first = out._lent[first.data.ctypes.data]
        assert out.send(first) is not None
        assert _wait(lambda: len(rx.got) == 1 and not out._in_flight)
        rx.keep = False  # the receiver keeps the first frame only
        assert rx.got[0][3][2:] == (9, int(_frame(9, (48, 64, 3)).data.sum() % 997))  # the pixels made in the slot
        assert out.in_place == 1 and copies.snapshot()["channel_copy"] == 0
        assert copies.snapshot()["channel_in_place"] == 1
        # this process lets go of the frame, the receiver keeps it: its slot is neither lent nor written again
        first = None
        gc.collect()
        second, third = made(20), made(21)
        assert second is not None and third is not None
        assert slot_of_first not in (out._lent[second.data.ctypes.data], out._lent[third.data.ctypes.data])
        assert made(22) is None and out.lend_refused == 1  # two lent frames referenced here: the rest for copies
        for v in (30, 31):  # frames made elsewhere are copied into the slot left, not sent in their messages
            assert out.send(_frame(v, (48, 64, 3))) is not None
            assert _wait(lambda: len(rx.got) == (v - 28) and not out._in_flight)
        assert copies.snapshot()["channel_copy"] == 2 and out.inline_frames == 0 and out.stats()["slots"] == 4
        assert int(rx.kept[0][0, 0, 0]) == 9  # the kept frame was not overwritten by anything after it
        rx.kept.clear()  # the receiver lets go of everything it kept
        gc.collect()
        second = third = None
        gc.collect()
        assert _wait(lambda: all(s.free for s in out._slots.values()))
        again = made(40)  # now a slot of theirs is lent again, and no new one is made
        assert again is not None and out._lent[again.data.ctypes.data] in out._slots and out.stats()["slots"] == 4
        assert out.send(again) is not None and _wait(lambda: len(rx.got) == 4)
        assert rx.got[3][3][2] == 40 and out.in_place == 2 and out.inline_frames == 0
    finally:
        out.close()
        srv.close()


_CLOSE_UNDER_FRAMES = """
import os, sys, time
import numpy as np
from aerodaas.actors.data.channel import ChannelServer, channel_address
from aerodaas.actors.data.channel_outlet import ChannelOutlet
from aerodaas.protocol.messages import FrameMsg, Port
key = os.urandom(32)
addr = channel_address(key, "close-under-frames/%d" % os.getpid())
kept = []
srv = ChannelServer(addr, key, lambda d: kept.append(d.msg.data) or [])
out = ChannelOutlet(addr, key, "a#1", Port("in"), buffer=1, reply_to=None, on_reply=lambda r: None)
lent = out.lend((48, 64, 3))
lent[:] = 7
lent.flags.writeable = False
out.send(FrameMsg(robot="d1", sim_t=0.0, data=lent))
deadline = time.monotonic() + 10
while not kept and time.monotonic() < deadline:
    time.sleep(0.01)
out.close()   # the sender's end goes while a lent frame here and a frame over there are still referenced
srv.close()
time.sleep(0.2)
print(int(lent.sum()), int(kept[0].sum()))
"""


def test_closing_a_channel_never_unmaps_a_frame_still_referenced_on_either_side():
    """An outlet closed while this process still references a frame made in its slot (the recorder still encoding
    it, the camera's latest frame) and a server whose sender went while its analytics still holds a frame: both
    frames stay readable (a crash, SIGSEGV, before the mappings were tied to the frames' lifetimes)."""
    r = subprocess.run([sys.executable, "-c", _CLOSE_UNDER_FRAMES], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
    assert r.stdout.split() == [str(7 * 48 * 64 * 3)] * 2, r.stdout


class _Unloadable:
    """Pickles fine, fails to unpickle (as a class the other process cannot import would)."""

    def __reduce__(self):
        return (_refuse, ())


def _refuse():
    raise ImportError("no module named 'their_plugin'")


def test_a_message_the_other_side_cannot_unpickle_fails_alone_and_the_channel_goes_on(address):
    """A delivery the receiver cannot unpickle is answered as failed (the sender's in-flight place is given back);
    an answer whose reply the sender cannot unpickle counts that delivery failed; either way the next frame goes
    through on the same connection."""
    replies: list = []

    def deliver(d: Delivery) -> list:
        if isinstance(d.msg, FrameMsg) and int(d.msg.data[0, 0, 0]) == 2:
            return [Delivery("drone/d1", Port("in"), ValueMsg(robot="d1", sim_t=2.0, data=_Unloadable()))]
        return Receiver()(d)

    srv = ChannelServer(address, KEY, deliver)
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=1, reply_to="drone/d1", on_reply=replies.extend)
    try:
        assert out.send(ValueMsg(robot="d1", sim_t=1.0, data=_Unloadable())) is not None
        assert _wait(lambda: out.failed == 1 and not out._in_flight) and srv.failed == 1
        assert out.send(_frame(2, (8, 8, 3))) is not None
        assert _wait(lambda: out.failed == 2 and not out._in_flight) and replies == []
        assert out.send(_frame(3, (8, 8, 3))) is not None
        assert _wait(lambda: len(replies) == 1)
        assert out.connected and out.reconnects == 0 and out.dropped == 0
    finally:
        out.close()
        srv.close()


def test_an_answer_to_a_delivery_no_longer_in_flight_is_dropped(address):
    """An answer for a delivery number the outlet no longer has in flight (it was closed and reopened meanwhile, or
    counted the delivery lost) is dropped: no reply handed on with metadata it cannot put back, nothing counted
    failed; the answer to the delivery in flight arrives as usual, with the sender's own FrameMeta object."""
    listener = mpc.Listener(address, family="AF_UNIX", authkey=KEY)

    def serve() -> None:  # a peer answering a stale number first, then the delivery's own
        conn = listener.accept()
        item = decode(conn.recv())
        d = item.delivery
        nav = NavigationMsg(robot="d1", sim_t=d.msg.sim_t, data=AeroNavigation(waypoints=[]), meta=d.msg.meta)
        reply = [Delivery("d1/scheduler", Port("priority", 1), nav)]
        conn.send(encode_done(ChannelDone(item.seq + 100, reply, None, ()), d.msg.meta))
        conn.send(encode_done(ChannelDone(item.seq, reply, None, ()), d.msg.meta))
        try:
            conn.recv()  # until the outlet closes
        except (EOFError, OSError):
            pass

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    replies: list = []
    out = ChannelOutlet(address, KEY, "detector#1", Port("in"), buffer=1, reply_to="drone/d1", on_reply=replies.extend)
    try:
        f = _frame(4, (8, 8, 3))
        f.meta = _meta(4, (8, 8, 3))
        assert out.send(f) is not None
        assert _wait(lambda: len(replies) == 1 and not out._in_flight)
        assert replies[0].msg.meta is f.meta and out.failed == 0 and out.connected
    finally:
        out.close()
        listener.close()
