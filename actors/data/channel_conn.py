"""The same-node channel's connection (:mod:`aerodaas.actors.data.channel`): a
:class:`multiprocessing.connection.Connection` that reads the socket in large chunks and keeps what it read ahead.

Why: the standard connection reads every message with two blocking reads (its 4-byte length, then its body), and
a blocking read releases the GIL and takes it back, so on the receiving side each message paid a second system call
and a second wait for the GIL — in a drone actor, whose clock and render threads hold the GIL often, a wait of up to
the interpreter's switch interval. Here one read usually brings a whole message (a frame's delivery, or its answer,
is a few hundred bytes).

The framing on the socket is the standard one, unchanged (a signed 32-bit big-endian length, ``-1`` then an unsigned
64-bit length for bodies over 2 GiB, then the body): either end may be a plain ``Connection``. The HMAC handshake
(:func:`multiprocessing.connection.deliver_challenge` / ``answer_challenge``) reads through the same buffer, so
nothing read ahead during it is lost. Messages are pickled with :func:`pickle.dumps` (the channel's wire tuples are
built-ins, :mod:`aerodaas.actors.data.channel_wire`: multiprocessing's reducers for sockets and connections never
apply) and unpickled straight from the buffer, without an intermediate ``BytesIO``. ``poll()`` is not supported
(it would not see messages already read ahead): the channel's threads block in :meth:`recv`.
"""
from __future__ import annotations

import io
import os
import pickle
import socket
import struct
from multiprocessing import connection as mpc
from typing import Any

__all__ = ["BufferedConnection", "client"]

#: bytes asked of the socket per read (a message larger than this is read in as many reads as it needs)
READ_SIZE = 65536
_LEN = struct.Struct("!i")
_LEN64 = struct.Struct("!Q")


class BufferedConnection(mpc.Connection):
    """A connection over a connected socket's file descriptor (owned: closed by :meth:`close`) that reads ahead into
    a buffer. Same interface and wire format as :class:`multiprocessing.connection.Connection`; :meth:`recv`
    raises EOFError when the peer closed between messages and OSError when it closed inside one."""

    def __init__(self, handle: int, readable: bool = True, writable: bool = True) -> None:
        super().__init__(handle, readable, writable)
        self._rbuf = bytearray()

    def _frame(self, maxsize: int | None = None) -> tuple[int, int] | None:
        """Read until the buffer holds one whole message; ``(offset, size)`` of its body in the buffer, or None
        when its size is over ``maxsize`` (the standard connection's ``recv_bytes(maxlength)`` rule). Raises
        EOFError / OSError as :meth:`recv`."""
        buf, handle = self._rbuf, self._handle
        while True:
            n = len(buf)
            if n >= 4:
                size, off = _LEN.unpack_from(buf)[0], 4
                if size == -1:
                    size, off = (_LEN64.unpack_from(buf, 4)[0], 12) if n >= 12 else (-1, 12)
                if size >= 0:
                    if maxsize is not None and size > maxsize:
                        return None
                    if n >= off + size:
                        return off, size
                    want = off + size - n
                else:
                    want = 12 - n
            else:
                want = 4 - n
            chunk = os.read(handle, max(READ_SIZE, want))
            if not chunk:
                if not buf:
                    raise EOFError
                raise OSError("got end of file during message")
            buf += chunk

    def _recv_bytes(self, maxsize: int | None = None) -> io.BytesIO | None:
        got = self._frame(maxsize)
        if got is None:
            return None
        off, size = got
        out = io.BytesIO(self._rbuf[off:off + size])
        del self._rbuf[:off + size]
        return out

    def recv(self) -> Any:
        """The next message, unpickled. Raises EOFError / OSError (the peer closed), what unpickling raises."""
        self._check_closed()
        self._check_readable()
        off, size = self._frame()
        buf = self._rbuf
        try:
            with memoryview(buf) as whole, whole[off:off + size] as body:  # released before the buffer shrinks
                return pickle.loads(body)
        finally:
            del buf[:off + size]

    def send(self, obj: Any) -> None:
        """Send ``obj`` pickled (one write for a message up to 16 KiB, header included). Raises what pickling or
        writing raises (OSError: the peer is gone)."""
        self._check_closed()
        self._check_writable()
        self._send_bytes(pickle.dumps(obj, pickle.HIGHEST_PROTOCOL))


def client(address: str, key: bytes) -> BufferedConnection:
    """Connect to the channel server at Unix socket ``address`` and authenticate with ``key`` both ways, as
    :func:`multiprocessing.connection.Client` does (answer the server's challenge, then challenge it). Raises
    OSError when nobody serves the address, :class:`multiprocessing.AuthenticationError` when the server does
    not hold ``key``."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        s.connect(address)
    except BaseException:
        s.close()
        raise
    conn = BufferedConnection(s.detach())
    try:
        mpc.answer_challenge(conn, key)
        mpc.deliver_challenge(conn, key)
    except BaseException:
        conn.close()
        raise
    return conn
