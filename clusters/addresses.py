"""Network addresses ``aerodaas run`` is given, checked before Ray starts and in bounded time: the Ray cluster of
``--address`` (parsed, port in range, host resolved and its port reachable within ``timeout_s``), and the HITL API's
host and port (parsed, in range, free here)."""
from __future__ import annotations

import socket
import ssl
import threading

from aerodaas.clusters.ray_tls import RayTLS

__all__ = ["ResolveError", "try_bind", "check_ray_address", "check_listen", "check_hitl"]


def _resolve(host: str, port: int, timeout_s: float) -> list:
    """``socket.getaddrinfo`` bounded by ``timeout_s`` (the resolver itself has no time-out: a thread waits)."""
    out: dict = {}

    def go() -> None:
        try:
            out["infos"] = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        except OSError as e:
            out["error"] = e

    t = threading.Thread(target=go, daemon=True, name="aerodaas-resolve")
    t.start()
    t.join(timeout_s)
    if t.is_alive():
        raise TimeoutError(f"resolving {host!r} took longer than {timeout_s:g} s")
    if "error" in out:
        raise out["error"]
    return out["infos"]


class ResolveError(OSError):
    """``host`` did not resolve (or not within the time-out); the message is the resolver's."""


def try_bind(host: str, port: int, timeout_s: float = 10.0) -> None:
    """Whether a TCP server could listen on ``host:port`` here: resolve ``host`` (bounded by ``timeout_s``
    seconds) and bind one socket to the first address (``SO_REUSEADDR``, closed at once; port 0 always binds).
    Raises ResolveError when ``host`` does not resolve in time, OSError when the address cannot be bound (port
    taken, not an address of this machine)."""
    try:
        infos = _resolve(host, port, timeout_s)
    except OSError as e:  # TimeoutError included
        raise ResolveError(str(e)) from e
    family, _, _, _, addr = infos[0]
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(addr)


def check_ray_address(address: str, timeout_s: float = 10.0, option: str = "--address") -> None:
    """Check a Ray cluster address ``HOST:PORT`` (or ``ray://HOST:PORT``; ``auto`` and ``local`` are Ray's own and
    left to it) before Ray is started: the port an integer in [1, 65535], the host resolvable and the port
    accepting a TCP connection and answering it as an HTTP/2 (gRPC) server does, as Ray's GCS does, within
    ``timeout_s`` seconds each. With Ray's TLS on in this environment (``RAY_USE_TLS``,
    :class:`aerodaas.clusters.ray_tls.RayTLS`) the HTTP/2 exchange runs inside a TLS handshake with its
    certificates, as Ray's own processes connect. Raises ValueError naming ``option`` and the address (or the
    ``RAY_TLS_*`` variable) and saying why."""
    a = address.strip()
    if a in ("auto", "local"):
        return
    body = a[len("ray://"):] if a.startswith("ray://") else a
    if body.startswith("["):
        host, _, port_s = body[1:].partition("]")
        port_s = port_s[1:] if port_s.startswith(":") else ""
    else:
        host, _, port_s = body.rpartition(":")
    if not host or not port_s:
        raise ValueError(f"{option} {address!r}: not HOST:PORT (the Ray head's GCS address, e.g. 10.0.0.5:6379)")
    try:
        port = int(port_s)
    except ValueError:
        raise ValueError(f"{option} {address!r}: port {port_s!r} is not an integer") from None
    if not 1 <= port <= 65535:
        raise ValueError(f"{option} {address!r}: port {port} is outside [1, 65535]")
    try:
        infos = _resolve(host, port, timeout_s)
    except (OSError, TimeoutError) as e:
        raise ValueError(f"{option} {address!r}: cannot resolve host {host!r} ({e})") from None

    tls = RayTLS.from_environ()  # Ray's TLS on (RAY_USE_TLS): the check speaks TLS as Ray's processes do
    family, kind, proto, _, addr = infos[0]
    with socket.socket(family, kind, proto) as s:
        s.settimeout(timeout_s)
        try:
            s.connect(addr)
        except OSError as e:
            raise ValueError(f"{option} {address!r}: no Ray cluster answers there ({e.strerror or e}; start one with "
                             f"`ray start --head` or `aerodaas up`)") from None
        if tls is not None:
            try:
                with tls.client_context().wrap_socket(s, server_hostname=host) as t:
                    why = _grpc_answer(t)
            except (ssl.SSLError, OSError) as e:  # socket.timeout included
                raise ValueError(f"{option} {address!r}: the TLS handshake with it failed ({e}; RAY_USE_TLS is set: "
                                 f"the cluster must run Ray's TLS with a certificate signed by RAY_TLS_CA_CERT, and it "
                                 f"must accept RAY_TLS_SERVER_CERT)") from None
        else:
            why = _grpc_answer(s)
    if why:
        raise ValueError(f"{option} {address!r}: the port accepts connections but is not a Ray cluster ({why} "
                         f"within {timeout_s:g} s; Ray's GCS and Ray Client server speak gRPC over HTTP/2; a cluster "
                         f"with Ray's TLS on answers only a client with RAY_USE_TLS=1 and its certificates): give the "
                         f"Ray head's GCS address (`ray start --head` prints it) or start one with `aerodaas up`")


#: an HTTP/2 client's connection preface and an empty SETTINGS frame (RFC 9113 section 3.4, 6.5)
_H2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 0x4, 0, 0, 0, 0, 0])


def _grpc_answer(s: socket.socket) -> str:
    """Whether the server on the connected socket ``s`` (its time-out set) speaks HTTP/2, as every gRPC server and
    so Ray's GCS does: send the client connection preface and read the server's first frame, which must be a
    SETTINGS frame (type 0x4; RFC 9113 section 3.4). Returns "" when it is, else why not. A port that accepts TCP but
    never answers (a ``--address`` to such a port hung ``ray.init`` for 821 s) ends at the socket's time-out."""
    try:
        s.sendall(_H2_PREFACE)
        head = b""
        while len(head) < 9:
            chunk = s.recv(9 - len(head))
            if not chunk:
                return "it closed the connection without an HTTP/2 SETTINGS frame"
            head += chunk
    except socket.timeout:
        return "no HTTP/2 SETTINGS frame came back"
    except OSError as e:
        return f"the connection failed: {e.strerror or e}"
    if head[3] != 0x4:
        return f"its first bytes {head[:9]!r} are not an HTTP/2 SETTINGS frame"
    return ""


def check_listen(host: object, port: object, option: str) -> tuple[str, int]:
    """Check that a server can listen on ``host:port`` here before Ray starts: ``host`` a non-empty string that
    resolves to an address of this machine, ``port`` an integer in [0, 65535] (0: any free port) that is free.
    Returns (host, port). Raises ValueError naming ``option`` and the value."""
    if not isinstance(host, str) or not host.strip():
        raise ValueError(f"{option}.host {host!r}: not a host name or address")
    if isinstance(port, bool) or not isinstance(port, int):
        raise ValueError(f"{option}.port {port!r}: not an integer")
    if not 0 <= port <= 65535:
        raise ValueError(f"{option}.port {port}: outside [0, 65535]")
    try:
        try_bind(host, port)
    except ResolveError as e:
        raise ValueError(f"{option}.host {host!r}: cannot resolve it ({e})") from None
    except OSError as e:
        raise ValueError(f"{option}.host / {option}.port {host}:{port}: cannot listen there "
                         f"({e.strerror or e})") from None
    return host, port


def check_hitl(cfg: object, opts: object) -> None:
    """When the run will serve the HITL API (``opts.hitl`` or ``cfg.hitl.enabled``), check its host and port
    (``opts.hitl_port`` over ``cfg.hitl.port``) with :func:`check_listen` before Ray starts. Raises ValueError
    naming ``hitl.host`` / ``hitl.port``."""
    h = cfg.hitl  # type: ignore[attr-defined]
    on = opts.hitl if getattr(opts, "hitl", None) is not None else h.enabled  # type: ignore[attr-defined]
    if not on:
        return
    port = opts.hitl_port if getattr(opts, "hitl_port", None) is not None else h.port  # type: ignore[attr-defined]
    check_listen(h.host, port, "hitl")
