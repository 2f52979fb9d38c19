"""Accept both Foxglove WebSocket subprotocol names in front of the foxglove-sdk server.

The Foxglove WebSocket protocol was published as ``foxglove.websocket.v1`` (``@foxglove/ws-protocol``'s
``FoxgloveClient.SUPPORTED_SUBPROTOCOL``, Foxglove's desktop/web app before the SDK) and is now served by
foxglove-sdk under ``foxglove.sdk.v1`` (spec: https://github.com/foxglove/foxglove-sdk/blob/main/docs/spec/websocket/
README.md). foxglove-sdk 0.30.3's server accepts only ``foxglove.sdk.v1``/``foxglove.sdk.v1.1`` and has no option to
add a name (``foxglove.start_server`` takes none; the names are constants in its Rust core), so a client offering
only ``foxglove.websocket.v1`` is answered HTTP 400 "Missing expected sec-websocket-protocol header".

:class:`SubprotocolFront` listens on the user's address and forwards every TCP connection to the SDK server on a
loopback port. Only the HTTP upgrade is touched (RFC 6455 section 4.1/4.2.2): when the client's
``Sec-WebSocket-Protocol`` offers ``foxglove.websocket.v1`` and no ``foxglove.sdk.*`` name, ``foxglove.sdk.v1`` is
offered to the SDK instead and the SDK's answer is renamed back to ``foxglove.websocket.v1``; every byte after the
handshake passes through unchanged (the two names denote the same frames).

:meth:`SubprotocolFront.hold` also closes a race of the SDK server (foxglove-sdk 0.30.3, ``connected_client.rs``,
``ConnectedClient::advertise_channels``): a channel created while a client is connected is *enqueued* for
advertisement before it is entered in the client's channel map, and the SDK's ``on_subscribe`` rejects a subscription
to a channel not in that map ("Unknown channel ID: N"). A client that subscribes as soon as it sees the advertisement
(Foxglove's app, ``@foxglove/ws-protocol``) can be answered so when the creating thread is descheduled between the two
steps (a loaded machine), and then never receives that channel. While :meth:`hold` is held (around the creation of a
channel: :meth:`aerodaas.liveview.server.LiveServer.advertise`), nothing the SDK sends is passed on to a client, so no
advertisement reaches a client before the SDK can accept its subscription.

Access (``aerodaas.clusters.tls``): with a TLS context the front terminates TLS (:class:`~aerodaas.liveview.tls_stream.
TlsStream`; the SDK server behind it stays on loopback) and serves ``wss://``; with a token it answers every upgrade
request that does not carry it ``401 Unauthorized`` and closes, before a byte reaches the SDK. A client presents the
token as the query parameter ``token`` of the URL (``wss://HOST:PORT/?token=...``: what a browser's WebSocket, and so
Foxglove's app, can send) or as an ``Authorization: Bearer ...`` header (RFC 6750; Node's ``ws``, Python's
``websockets``); the parameter is removed from the request before it is forwarded, so the SDK never sees it.
"""
from __future__ import annotations

import re
import secrets
import socket
import ssl
import struct
import threading
from collections.abc import Callable
from urllib.parse import parse_qsl, urlencode

from aerodaas.liveview.tls_stream import TlsStream

__all__ = ["LEGACY", "SDK", "SubprotocolFront", "authorize"]

LEGACY = "foxglove.websocket.v1"
SDK = "foxglove.sdk.v1"
_MAX_HEADER = 64 * 1024  # an HTTP upgrade request is a few hundred bytes; bound what we buffer
_PROTO_LINE = re.compile(rb"(?im)^sec-websocket-protocol:[ \t]*([^\r\n]*)\r\n")
_AUTH_LINE = re.compile(rb"(?im)^authorization:[ \t]*bearer[ \t]+([^\r\n]*?)[ \t]*\r\n")
_UNAUTHORIZED = (b"HTTP/1.1 401 Unauthorized\r\nWWW-Authenticate: Bearer\r\nContent-Type: text/plain\r\n"
                 b"Content-Length: 47\r\nConnection: close\r\n\r\nmissing or invalid token (?token=... or Bearer)")


def _read_header(sock: socket.socket) -> tuple[bytes, bytes]:
    """Read up to the end of an HTTP header (``\\r\\n\\r\\n``) -> ``(header, rest)``; ``(b"", b"")`` on EOF/overflow."""
    buf = b""
    while b"\r\n\r\n" not in buf:
        chunk = sock.recv(4096)
        if not chunk or len(buf) > _MAX_HEADER:
            return b"", b""
        buf += chunk
    i = buf.index(b"\r\n\r\n") + 4
    return buf[:i], buf[i:]


def rewrite_request(header: bytes) -> tuple[bytes, bool]:
    """Offer ``foxglove.sdk.v1`` for a request that offers only ``foxglove.websocket.v1`` -> ``(header, renamed)``."""
    m = _PROTO_LINE.search(header)
    if m is None:
        return header, False
    offered = [p.strip() for p in m.group(1).decode("latin-1").split(",")]
    if LEGACY not in offered or any(p.startswith("foxglove.sdk.") for p in offered):
        return header, False
    line = f"Sec-WebSocket-Protocol: {SDK}\r\n".encode()
    return header[:m.start()] + line + header[m.end():], True


def authorize(header: bytes, token: str) -> tuple[bytes, bool]:
    """Check the upgrade request ``header`` for ``token`` (the query parameter ``token`` or an ``Authorization:
    Bearer`` header, compared in constant time) -> ``(header without the token parameter, accepted)``."""
    line_end = header.find(b"\r\n")
    parts = header[:line_end].split(b" ")
    if line_end < 0 or len(parts) != 3:
        return header, False
    path, _, query = parts[1].partition(b"?")
    pairs = parse_qsl(query.decode("latin-1"), keep_blank_values=True)
    given = [v for k, v in pairs if k == "token"]
    m = _AUTH_LINE.search(header)
    if m is not None:
        given.append(m.group(1).decode("latin-1"))
    ok = any(secrets.compare_digest(g.encode("latin-1"), token.encode()) for g in given)
    rest = urlencode([(k, v) for k, v in pairs if k != "token"]).encode("latin-1")
    target = path + (b"?" + rest if rest else b"")
    return b" ".join((parts[0], target, parts[2])) + header[line_end:], ok


def rewrite_response(header: bytes) -> bytes:
    """Rename the SDK's chosen ``foxglove.sdk.v1`` back to ``foxglove.websocket.v1`` in its 101 answer."""
    m = _PROTO_LINE.search(header)
    if m is None or m.group(1).strip() != SDK.encode():
        return header
    return header[:m.start()] + f"Sec-WebSocket-Protocol: {LEGACY}\r\n".encode() + header[m.end():]


def _pipe(src: socket.socket, dst: socket.socket, gate: threading.Lock | None = None,
          on_stall: Callable[[], None] | None = None) -> None:
    """Copy ``src`` to ``dst`` until EOF; with ``gate``, each chunk waits while the gate is held (a chunk received
    before someone took the gate was produced before, so only what the SDK sends during a hold is held back).
    A send to ``dst`` that times out (its ``SO_SNDTIMEO``: the reader stopped reading and the kernel's buffers are
    full) ends the connection and calls ``on_stall``."""
    try:
        while True:
            data = src.recv(65536)
            if not data:
                break
            if gate is not None:
                with gate:
                    pass
            dst.sendall(data)
    except (BlockingIOError, TimeoutError):
        if on_stall is not None:
            on_stall()
    except OSError:
        pass
    finally:
        for s in (dst, src):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass


class SubprotocolFront:
    """Listen on ``host:port`` (0 = any free port) and forward to ``127.0.0.1:backend_port``, renaming the
    subprotocol as the module docstring describes; with ``context`` over TLS, with ``token`` only for clients that
    present it (module docstring). ``port`` is the port bound. Raises ``OSError`` when the address
    cannot be bound. :meth:`close` stops accepting and closes the connections it forwards.

    A client that stops reading is dropped: once the kernel's buffers towards it are full (the bounded queue, with
    the SDK's own ``backlog`` behind it), a send that waits ``send_timeout_s`` seconds ends its connection, counted
    in ``dropped`` and told to ``on_drop(peer address)``; it never holds the run (a client that stopped reading
    held the end of a run for ~120 s before)."""

    def __init__(self, host: str, port: int, backend_port: int, send_timeout_s: float = 10.0,
                 on_drop: Callable[[str], None] | None = None, context: ssl.SSLContext | None = None,
                 token: str | None = None) -> None:
        self._context, self._token = context, token
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._listen = socket.socket(family, socket.SOCK_STREAM)
        self._listen.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listen.bind((host, port))
        self._listen.listen(64)
        self.port = int(self._listen.getsockname()[1])
        self._backend = ("127.0.0.1", int(backend_port))
        self._conns: list[socket.socket] = []
        self._lock = threading.Lock()
        self._gate = threading.Lock()  # held by hold(): the SDK's bytes wait before going to a client
        self._closed = False
        self.send_timeout_s, self._on_drop = float(send_timeout_s), on_drop
        self.dropped = 0
        threading.Thread(target=self._accept, name="foxglove-front", daemon=True).start()

    def _accept(self) -> None:
        while not self._closed:
            try:
                client, _ = self._listen.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(client,), daemon=True).start()

    def _serve(self, client: socket.socket) -> None:
        raw = client
        try:
            backend = socket.create_connection(self._backend, timeout=10)
            backend.settimeout(None)
        except OSError:
            client.close()
            return
        with self._lock:
            if self._closed:
                client.close()
                backend.close()
                return
            self._conns += [client, backend]
        try:
            client.settimeout(10)
            if self._context is not None:
                tls = TlsStream(raw, self._context)
                tls.handshake()
                client = tls  # type: ignore[assignment]
            header, rest = _read_header(client)
            client.settimeout(None)
            if not header:
                raise OSError("no HTTP header")
            if self._token is not None:
                header, ok = authorize(header, self._token)
                if not ok:
                    client.sendall(_UNAUTHORIZED)
                    raise OSError("no valid token")
            header, renamed = rewrite_request(header)
            backend.sendall(header + rest)
            if renamed:
                answer, rest = _read_header(backend)
                if not answer:
                    raise OSError("no HTTP answer")
                with self._gate:  # ``rest`` may hold an advertisement already (see hold)
                    pass
                client.sendall(rewrite_response(answer) + rest)
        except (OSError, ssl.SSLError):
            try:
                raw.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            raw.close()
            backend.close()
            return
        sec = int(self.send_timeout_s)
        client.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO,
                          struct.pack("ll", sec, int((self.send_timeout_s - sec) * 1e6)))
        try:
            peer = "%s:%s" % client.getpeername()[:2]
        except OSError:
            peer = "?"
        threading.Thread(target=_pipe, args=(backend, client, self._gate, lambda: self._dropped(peer)),
                         daemon=True).start()
        _pipe(client, backend)

    def _dropped(self, peer: str) -> None:
        self.dropped += 1
        if self._on_drop is not None:
            self._on_drop(peer)

    def hold(self) -> threading.Lock:
        """A context manager: while it is held, what the SDK server sends waits in the front instead of reaching
        the clients (module docstring). Hold it around the creation of a channel, nothing longer."""
        return self._gate

    def close(self) -> None:
        """Stop listening and close every forwarded connection. Idempotent."""
        self._closed = True
        try:
            self._listen.shutdown(socket.SHUT_RDWR)  # wakes the accept() of the other thread (Linux)
        except OSError:
            pass
        try:
            self._listen.close()
        except OSError:
            pass
        with self._lock:
            conns, self._conns = self._conns, []
        for s in conns:
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            s.close()
