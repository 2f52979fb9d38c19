"""The same-node channel's connection (aerodaas.actors.data.channel_conn): the standard framing either way with a
plain multiprocessing connection, messages that arrive together or in pieces, the run's key checked both ways."""
from __future__ import annotations

import os
import socket
import threading
from multiprocessing import AuthenticationError
from multiprocessing import connection as mpc

import pytest

from aerodaas.actors.data.channel_conn import READ_SIZE, BufferedConnection, client

KEY = os.urandom(32)


def pair() -> tuple[BufferedConnection, mpc.Connection]:
    a, b = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    return BufferedConnection(a.detach()), mpc.Connection(b.detach())


def test_messages_sent_together_arrive_one_by_one_in_order_both_ways():
    ours, plain = pair()
    try:
        ours.send(("d", 1, [], None, ()))
        assert plain.recv() == ("d", 1, [], None, ())
        msgs = [("f", i, "x" * i, {"t": i / 3}) for i in range(50)]
        for m in msgs:  # all written before the first read: one read brings many of them
            plain.send(m)
        plain.send_bytes(b"raw")
        plain.close()  # a message lost in the buffer would show as EOF below, not as a wait
        assert [ours.recv() for _ in msgs] == msgs
        assert ours.recv_bytes() == b"raw"
        with pytest.raises(EOFError):
            ours.recv()
    finally:
        ours.close()


def test_a_message_larger_than_one_read_and_eof_between_and_inside_messages():
    ours, plain = pair()
    big = os.urandom(5 * READ_SIZE + 17)
    t = threading.Thread(target=lambda: (plain.send(("o", 1, big)), plain.send(2)))
    t.start()
    assert ours.recv() == ("o", 1, big) and ours.recv() == 2
    t.join()
    plain.close()
    with pytest.raises(EOFError):  # closed between messages
        ours.recv()
    ours.close()
    a, b = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    ours = BufferedConnection(a.detach())
    b.sendall(b"\x00\x00\x01\x00" + b"cut")  # a 256-byte message of which 3 bytes came
    b.close()
    with pytest.raises(OSError, match="end of file during message"):
        ours.recv()
    ours.close()


def test_client_authenticates_with_the_key_both_ways():
    address = "\0aerodaas-test-conn-" + os.urandom(8).hex()
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(address)
    srv.listen(2)
    seen: list = []

    def serve(key: bytes) -> None:
        s, _ = srv.accept()
        conn = BufferedConnection(s.detach())
        try:
            mpc.deliver_challenge(conn, key)
            mpc.answer_challenge(conn, key)
            seen.append(conn.recv())
            conn.send("welcome")
        except (AuthenticationError, EOFError, OSError) as e:
            seen.append(type(e).__name__)
        finally:
            conn.close()

    try:
        t = threading.Thread(target=serve, args=(KEY,))
        t.start()
        c = client(address, KEY)
        c.send("hello")
        assert c.recv() == "welcome"
        c.close()
        t.join()
        t = threading.Thread(target=serve, args=(os.urandom(32),))  # a server without the run's key
        t.start()
        with pytest.raises(AuthenticationError):
            client(address, KEY)
        t.join()
        assert seen[0] == "hello" and seen[1] in ("AuthenticationError", "EOFError", "OSError")
    finally:
        srv.close()
