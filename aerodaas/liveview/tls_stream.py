"""Server-side TLS over a connected socket for a front that reads and writes a connection from two threads.

OpenSSL forbids using one ``SSL`` object from two threads at once, and :class:`ssl.SSLSocket` has no lock of its own,
so the front's two pipes (client -> server and server -> client, :mod:`aerodaas.liveview.subprotocol`) cannot share
an ``SSLSocket``. :class:`TlsStream` keeps the TLS state in an :class:`ssl.SSLObject` over two
:class:`ssl.MemoryBIO`\\ s (Python's :mod:`ssl`, "Memory BIO support"): every call into it holds one lock and only
moves bytes in memory; the socket's own reads and writes happen outside that lock, the writes in order under a
second lock (a TLS record's sequence number must match its position on the wire, RFC 8446 section 5.3).
"""
from __future__ import annotations

import socket
import ssl
import threading

__all__ = ["TlsStream"]

_RAW = 16384  # bytes read from the socket at a time (one TLS record at most carries 16 KiB)


class TlsStream:
    """A TLS server connection over ``sock`` with the socket calls a pipe uses: :meth:`recv` (decrypted bytes;
    ``b""`` at the end), :meth:`sendall`, :meth:`shutdown`, :meth:`close`, :meth:`setsockopt`,
    :meth:`getpeername`, :meth:`settimeout`. One thread may read while another writes. :meth:`handshake` first
    (raises ``ssl.SSLError``/``OSError`` when the client does not complete it)."""

    def __init__(self, sock: socket.socket, context: ssl.SSLContext) -> None:
        self.sock = sock
        self._in, self._out = ssl.MemoryBIO(), ssl.MemoryBIO()
        self._obj = context.wrap_bio(self._in, self._out, server_side=True)
        self._state = threading.Lock()  # every call into the SSLObject and its BIOs
        self._send = threading.Lock()  # taking encrypted bytes from _out and writing them to the socket

    def _flush(self) -> None:
        with self._send:
            with self._state:
                out = self._out.read()
            if out:
                self.sock.sendall(out)

    def _feed(self) -> bool:
        """Read what the socket has into the SSLObject; False at the socket's end."""
        raw = self.sock.recv(_RAW)
        with self._state:
            if raw:
                self._in.write(raw)
            else:
                self._in.write_eof()
        return bool(raw)

    def handshake(self) -> None:
        """The TLS handshake (the socket's timeout bounds each read)."""
        while True:
            try:
                with self._state:
                    self._obj.do_handshake()
                self._flush()
                return
            except ssl.SSLWantReadError:
                self._flush()
                if not self._feed():
                    raise ConnectionError("the client closed the connection during the TLS handshake") from None

    def recv(self, n: int) -> bytes:
        """Up to ``n`` decrypted bytes; ``b""`` once the client closed (with or without a TLS close_notify)."""
        while True:
            with self._state:
                try:
                    data: bytes | None = self._obj.read(n)
                except ssl.SSLWantReadError:
                    data = None
                except (ssl.SSLZeroReturnError, ssl.SSLEOFError):
                    data = b""
                pending = self._out.pending
            if pending:  # post-handshake messages (an alert, a key update answer)
                self._flush()
            if data is not None:
                return data
            if not self._feed():
                with self._state:
                    try:
                        return self._obj.read(n)
                    except ssl.SSLError:
                        return b""

    def sendall(self, data: bytes) -> None:
        """Encrypt ``data`` and write it; raises what the socket's ``sendall`` raises (its ``SO_SNDTIMEO``)."""
        with self._send:
            with self._state:
                view = memoryview(data)
                while view:  # a memory BIO takes it all; the loop only guards a partial write
                    view = view[self._obj.write(view):]
                out = self._out.read()
            self.sock.sendall(out)

    def shutdown(self, how: int) -> None:
        self.sock.shutdown(how)

    def close(self) -> None:
        self.sock.close()

    def setsockopt(self, *args: object) -> None:
        self.sock.setsockopt(*args)  # type: ignore[arg-type]

    def getpeername(self) -> object:
        return self.sock.getpeername()

    def settimeout(self, t: float | None) -> None:
        self.sock.settimeout(t)
