"""Live view: a run, or a recording, served to Foxglove over the Foxglove WebSocket protocol.

The server is the ``foxglove-sdk`` package's (``foxglove.start_server``; protocol ``foxglove.websocket.v1``,
https://github.com/foxglove/foxglove-sdk/blob/main/docs/spec/websocket/README.md). It is fed by the same bytes as the
MCAP file: :class:`LiveServer` is a sink of :class:`aerodaas.recording.writer.McapRecorder` (:meth:`McapRecorder.add_sink`),
so every channel has the recording's topic, schema name, schema encoding and schema data, and every message the
recorded bytes and log time. One serializer, two outputs: what Foxglove shows live is what the file holds.

* ``aerodaas run APP.py --live [HOST:PORT]``: the run's recorder (in the edge host process, where the drones and
  cameras are) also serves the live view; without ``--record`` nothing is written to disk. The server stops when
  the run ends (after the recording is finished).
* ``aerodaas replay FILE.mcap --live [HOST:PORT] [--speed K]``: :func:`replay` serves a recording at ``K`` times
  real time (log-time spacing kept), by default once a client has subscribed.

The server binds loopback (``127.0.0.1:8765``) unless an address is given. The protocol has no authentication of
its own: off loopback the front (:mod:`aerodaas.liveview.subprotocol`) serves ``wss://`` with the run's certificate
and asks every client for a token (``access``: :class:`aerodaas.clusters.tls.ServeAccess`; :func:`live_access` builds
it from the command line, before Ray starts).
Clients may offer either subprotocol name, ``foxglove.sdk.v1`` (the SDK's) or ``foxglove.websocket.v1`` (Foxglove's
``@foxglove/ws-protocol`` client): :mod:`aerodaas.liveview.subprotocol` fronts the SDK server, which accepts only the
first.

Nothing is lost for a client that subscribes to a channel soon after it is advertised (within ``catchup_s``): the
messages the channel carried before the subscription are sent to that client alone (the SDK's per-sink ``log``), so a
client connected from the start receives every message of every channel, once and in order (during that window a
channel's messages go to each caught-up client by its sink id, not by broadcast: see :meth:`LiveServer.publish`); a later subscriber to a latched topic
(:data:`LATCHED_SUFFIXES`: mission plan, camera calibration, mission result, a tracking analytics' 3-D scene and its
``LocationFixes``, the current tracks on the map) receives its latest message. Channels the run declares from its plan (the track
channels, :mod:`aerodaas.perception.track_records`) are advertised before their first message. At
:meth:`LiveServer.stop` the server waits (bounded: ``CATCHUP_WAIT_S``) until every client that follows every channel
has subscribed to the ones advertised last, so the last channel of a run (``/mission/result``) reaches it before the
server closes; a client that follows only some channels (Foxglove's app: its panels' topics) is not waited for.
"""
from __future__ import annotations

import math
import os
import re
import secrets
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from urllib.parse import quote

from aerodaas.clusters.addresses import ResolveError, try_bind
from aerodaas.clusters.tls import ServeAccess, check_exposure, is_loopback, state_dir, write_private_json
from aerodaas.liveview.subprotocol import SubprotocolFront
from aerodaas.recording.reader import _iter_raw, _open_mcap
from aerodaas.recording.writer import RecordedMessage

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "LATCHED_SUFFIXES", "LiveServer", "check_bindable", "live_access",
           "parse_address", "replay", "write_live_state"]

#: topics ending so keep their latest message for late subscribers (ROS's "latched" topics)
LATCHED_SUFFIXES = ("mission/plan", "camera_info", "calibration", "mission/result", "tracks/scene", "tracks/fixes")

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765  # Foxglove's default for its WebSocket connection


def parse_address(text: str | None, option: str = "--live") -> tuple[str, int]:
    """``HOST:PORT``, ``:PORT``, ``PORT`` or ``HOST`` (IPv6 as ``[::1]:PORT``) -> ``(host, port)``; missing parts
    default to ``127.0.0.1`` and ``8765``; port 0 means any free port. Raises ``ValueError`` naming ``option`` and
    the value for an empty host, a port that is not an integer in [0, 65535], or an unbracketed IPv6 address."""
    if text is None or text.strip() == "":
        return DEFAULT_HOST, DEFAULT_PORT
    s = text.strip()
    host, port_s = s, ""
    if s.startswith("["):
        end = s.find("]")
        if end < 0:
            raise ValueError(f"{option}: {text!r} is not HOST:PORT (unclosed '[' of an IPv6 address)")
        host, rest = s[1:end], s[end + 1:]
        if rest and not rest.startswith(":"):
            raise ValueError(f"{option}: {text!r} is not HOST:PORT")
        port_s = rest[1:]
    elif s.count(":") == 1:
        host, port_s = s.split(":")
    elif s.count(":") > 1:
        raise ValueError(f"{option}: {text!r}: write an IPv6 address in brackets, e.g. [::1]:8765")
    elif s.isdigit():
        host, port_s = "", s
    host = host or DEFAULT_HOST
    if not port_s:
        port = DEFAULT_PORT
    else:
        try:
            port = int(port_s)
        except ValueError:
            raise ValueError(f"{option}: port {port_s!r} in {text!r} is not an integer") from None
    if not 0 <= port <= 65535:
        raise ValueError(f"{option}: port {port} in {text!r} is outside [0, 65535]")
    return host, port


def check_bindable(host: str, port: int, option: str = "--live") -> None:
    """Raise ``ValueError`` naming ``option`` when ``host:port`` cannot be listened on here (port taken, address not
    of this machine, host not resolved within 10 s), so that ``aerodaas run --live`` fails before anything starts.
    Port 0 always works."""
    try:
        try_bind(host, port)
    except ResolveError as e:
        raise ValueError(f"{option}: cannot resolve {host!r} ({e})") from None
    except OSError as e:
        raise ValueError(f"{option}: cannot listen on {host}:{port} ({e.strerror or e})") from None


def live_access(host: str, cert: str | None, key: str | None, insecure: bool, option: str = "--live") -> ServeAccess:
    """The live view's access on ``host`` (:mod:`aerodaas.clusters.tls`): TLS with ``cert``/``key`` (checked), and a
    token off loopback (``$AERODAAS_LIVE_TOKEN``, else generated: 32 random bytes, base64url) or whenever
    ``$AERODAAS_LIVE_TOKEN`` is set. Raises ``ValueError`` naming the flag and value (no certificate off loopback
    without ``--insecure``, a bad certificate or key file, a token in ``$AERODAAS_LIVE_TOKEN`` that is not 16 to 256
    URL-safe characters)."""
    check_exposure(host, cert, key, insecure, option, "--tls-cert", "--tls-key", "--insecure")
    token = os.environ.get("AERODAAS_LIVE_TOKEN") or None
    if token is not None and not re.fullmatch(r"[A-Za-z0-9\-._~]{16,256}", token):
        raise ValueError("AERODAAS_LIVE_TOKEN: 16 to 256 characters of A-Z a-z 0-9 - . _ ~ (it travels in a URL)")
    if token is None and not is_loopback(host):
        token = secrets.token_urlsafe(32)
    return ServeAccess(cert, key, token, insecure and cert is None and not is_loopback(host))


def write_live_state(url: str, access: ServeAccess) -> "Path":
    """Hand the live view's connection to this user: ``$AERODAAS_STATE_DIR/live.json`` (mode 0600:
    :func:`aerodaas.clusters.tls.write_private_json`) with ``url``, ``token``, ``url_with_token`` (what Foxglove's
    "Open connection" takes) and ``cafile`` (the certificate to trust). Returns the file's path."""
    f = state_dir() / "live.json"
    for wildcard in ("://0.0.0.0:", "://[::]:"):  # bound on every address: a client here reaches it as localhost
        url = url.replace(wildcard, "://localhost:")
    write_private_json(f, {"url": url, "token": access.token, "pid": os.getpid(),
                           "url_with_token": f"{url}/?token={quote(access.token or '', safe='')}",
                           "cafile": os.path.abspath(access.cert_file) if access.cert_file else None})
    return f


class LiveServer:
    """A Foxglove WebSocket server (``foxglove-sdk``) publishing :class:`~aerodaas.recording.writer.RecordedMessage`\\ s.

    ``address`` is parsed by :func:`parse_address`. Channels are created on a topic's first message (or ahead with
    :meth:`advertise`) in a context of their own (nothing leaks into foxglove's global context). :meth:`publish`
    is thread-safe and does not block: the SDK queues per client (``backlog`` messages; the oldest data message is
    dropped for a slow client) and sends from its own threads; a client that stops reading altogether is dropped
    once a send to it waited ``client_send_timeout_s`` (listed in ``dropped_clients``; the recorder records a
    ``live_client_dropped`` event), so it never holds the run's end. ``playback_range`` (ns) announces a replay's time
    range; ``listener`` is told of subscriptions (``on_subscribe``/``on_unsubscribe``, a
    ``foxglove.websocket.ServerListener`` subset).

    ``access``: TLS and the token clients must present (module docstring; None: plain, no token, which only a
    loopback address may be). The constructor applies the exposure rule of every server
    (:func:`aerodaas.clusters.tls.check_exposure`) before it binds: off loopback a token, and TLS or
    ``access.insecure``; :attr:`insecure` then says whether it serves in clear text off loopback.

    Raises ``ValueError`` for a bad address or an exposure the rule refuses (naming the ``ServeAccess`` field), and
    ``RuntimeError`` naming the address when the server cannot bind.

    Limitation: during a channel's catch-up window its messages go to each client by sink id, and the SDK's Python
    ``Client`` exposes only its client id (foxglove-sdk 0.30). A connection's ClientId and SinkId are allocated
    together (``connected_client.rs``) from process-wide counters, so they agree as long as nothing else in the
    process creates a foxglove-sdk sink (``foxglove.open_mcap``, a second server). Our recorder writes MCAP with the
    ``mcap`` package, not the SDK; an app that opens an SDK sink in the edge host would misdirect the window's
    messages (the recording is unaffected).
    """

    #: at :meth:`stop`, how long (s) to wait for a client that follows every channel to subscribe to the ones
    #: advertised last (3 s was too short for Foxglove's npm client under load: it missed ``/mission/result``)
    CATCHUP_WAIT_S = 10.0
    #: at :meth:`stop`, how long (s) the SDK's server may take to stop before the connections it still serves are
    #: closed under it (a client that stopped reading held it ~120 s)
    STOP_WAIT_S = 5.0

    def __init__(self, address: str | None = None, *, name: str = "aerodaas", backlog: int = 1024,
                 listener: Any = None, time_capability: bool = False, catchup_s: float = 5.0,
                 catchup_messages: int = 256, catchup_bytes: int = 32 << 20, client_send_timeout_s: float = 10.0,
                 access: ServeAccess | None = None) -> None:
        import foxglove  # lazy: heavy foxglove
        from foxglove.websocket import Capability  # lazy: heavy foxglove

        self.host, port = parse_address(address)
        self.access = access or ServeAccess()
        # the exposure rule of every server (aerodaas.clusters.tls), here too and not only in `aerodaas run/replay`
        self.access.check(self.host, f"LiveServer({address!r})")
        self.client_send_timeout_s = float(client_send_timeout_s)
        self._foxglove = foxglove
        self._ctx = foxglove.Context()
        self._channels: dict[str, Any] = {}
        self._lock = threading.RLock()
        self.published = 0
        self.stopped = False
        self.subscriptions = 0  # subscriptions open now, over all clients
        self._user_listener = listener
        self.catchup_s, self._catchup_n, self._catchup_bytes = float(catchup_s), int(catchup_messages), catchup_bytes
        self._born: dict[str, float] = {}  # topic -> monotonic time of its advertisement
        self._early: dict[str, list[tuple[bytes, int]]] = {}  # topic -> messages of its first catchup_s
        self._early_bytes: dict[str, int] = {}
        self._latest: dict[str, tuple[bytes, int]] = {}  # latched topic -> its latest message
        self._client_subs: dict[int, set[str]] = {}  # client id -> topics subscribed
        self.catchup_sent = 0
        #: clients dropped for not reading (their address, ``time.time()``): see :class:`SubprotocolFront`
        self.dropped_clients: list[tuple[str, float]] = []
        try:  # the SDK on a loopback port of its own, fronted for both subprotocol names (module docstring)
            self._server = foxglove.start_server(name=name, host="127.0.0.1", port=0, context=self._ctx,
                                                 message_backlog_size=backlog, server_listener=self,
                                                 capabilities=[Capability.Time] if time_capability else None)
        except Exception as e:  # the SDK raises its own error type for bind failures
            raise RuntimeError(f"live view: cannot start the foxglove-sdk server ({e})") from e
        try:
            self._front = SubprotocolFront(self.host, port, int(self._server.port),
                                           send_timeout_s=client_send_timeout_s, on_drop=self._client_dropped,
                                           context=self.access.context(), token=self.access.token)
        except OSError as e:
            self._server.stop()
            raise RuntimeError(f"live view: cannot serve on {self.host}:{port} ({e.strerror or e})") from e
        self.port = self._front.port

    def _client_dropped(self, peer: str) -> None:
        self.dropped_clients.append((peer, time.time()))

    @property
    def insecure(self) -> bool:
        """Whether this server serves plain WebSocket off loopback (``access.insecure``): what a summary repeats."""
        return self.access.clear_text_off_loopback(self.host)

    @property
    def url(self) -> str:
        """``ws://HOST:PORT``, ``wss://`` with TLS (what Foxglove's "Open connection" -> "Foxglove WebSocket" takes;
        with a token, add ``/?token=...``). Never the token itself."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'wss' if self.access.tls else 'ws'}://{host}:{self.port}"

    def advertise(self, topic: str, schema_name: str, schema_encoding: str, schema_data: bytes,
                  message_encoding: str) -> Any:
        """The channel of ``topic`` (created and advertised to clients on first call)."""
        with self._lock:
            ch = self._channels.get(topic)
            if ch is None:
                schema = self._foxglove.Schema(name=schema_name, encoding=schema_encoding, data=bytes(schema_data))
                # the SDK enqueues the advertisement before it can accept a subscription to the channel: hold it in
                # the front until the channel is created (aerodaas.liveview.subprotocol, SubprotocolFront.hold)
                with self._front.hold():
                    ch = self._foxglove.Channel(topic, schema=schema, message_encoding=message_encoding,
                                                context=self._ctx)
                self._channels[topic] = ch
                self._born[topic] = time.monotonic()
                self._early[topic], self._early_bytes[topic] = [], 0
            return ch

    def publish(self, msg: RecordedMessage) -> None:
        """Send one recorded message to the clients subscribed to its topic (a :class:`McapRecorder` sink)."""
        if self.stopped:
            return
        ch = self._channels.get(msg.topic) or self.advertise(msg.topic, msg.schema_name, msg.schema_encoding,
                                                             msg.schema_data, msg.message_encoding)
        data = bytes(msg.data)
        with self._lock:  # ordered against on_subscribe's catch-up, so no message is sent twice or out of order
            t = msg.topic
            early = self._early.get(t)
            if early is not None and not (time.monotonic() - self._born[t] <= self.catchup_s
                                          and len(early) < self._catchup_n
                                          and self._early_bytes[t] + len(data) <= self._catchup_bytes):
                early = self._early[t] = None  # type: ignore[assignment]  # the window is over: free it
            if early is None:
                ch.log(data, log_time=msg.log_time_ns)  # to every subscriber
            else:
                # the catch-up window: only to the clients whose catch-up was sent. The SDK subscribes a client's
                # sink *before* it calls on_subscribe (foxglove-sdk connected_client.rs, since its PR #533): a
                # broadcast in between would reach the client ahead of its catch-up, which then repeats it, out of
                # order (seen at load 11). A client not caught up yet gets this message with its catch-up instead
                early.append((data, msg.log_time_ns))
                self._early_bytes[t] += len(data)
                # the SDK's Python Client has only its id, used as the sink id: see the class docstring
                for cid, topics in self._client_subs.items():
                    if t in topics:
                        ch.log(data, log_time=msg.log_time_ns, sink_id=cid)
            if t.endswith(LATCHED_SUFFIXES):
                self._latest[t] = (data, msg.log_time_ns)
        self.published += 1

    # foxglove.websocket.ServerListener (called from the SDK's threads)
    def on_subscribe(self, client: Any, channel: Any) -> None:
        """Count the subscription and send the new subscriber what it missed (module docstring)."""
        topic = channel.topic
        with self._lock:
            self.subscriptions += 1
            self._client_subs.setdefault(client.id, set()).add(topic)
            ch = self._channels.get(topic)
            # the window is open as long as publish() keeps its messages (it decides, under this lock)
            backlog: list[tuple[bytes, int]] = list(self._early.get(topic) or []) if ch is not None else []
            latest = self._latest.get(topic)
            if latest is not None and (not backlog or backlog[-1] != latest):
                backlog.append(latest)
            for data, t in backlog:
                ch.log(data, log_time=t, sink_id=client.id)
                self.catchup_sent += 1
        if self._user_listener is not None:
            self._user_listener.on_subscribe(client, channel)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self._lock:
            self.subscriptions -= 1
            self._client_subs.get(client.id, set()).discard(channel.topic)
        if self._user_listener is not None:
            self._user_listener.on_unsubscribe(client, channel)

    def broadcast_time(self, t_ns: int) -> None:
        """Tell clients the server's current time (ns), when built with ``time_capability``."""
        self._server.broadcast_time(int(t_ns))

    def stop(self, linger_s: float = 1.0) -> None:
        """Stop publishing, give subscribed clients ``linger_s`` seconds to receive what the server still queues
        for them (stopping drops it), then close the channels and stop the server (clients are disconnected).
        Idempotent."""
        if self.stopped:
            return
        self.stopped = True
        if linger_s > 0 and self.subscriptions > 0:
            # a client that follows every channel gets the ones advertised last (the mission result) first: it lacks
            # only channels of the last CATCHUP_WAIT_S, and the wait for it is bounded by that; a client that
            # follows a few channels (Foxglove's app: the topics of its panels) is not waited for
            t0 = time.monotonic()
            deadline = t0 + max(self.CATCHUP_WAIT_S, linger_s)
            while time.monotonic() < deadline:
                with self._lock:
                    topics = set(self._channels)
                    recent = {t for t in topics if self._born.get(t, 0.0) >= t0 - self.CATCHUP_WAIT_S}
                    missing = [c for c, subs in self._client_subs.items()
                               if subs and not topics <= subs and topics - subs <= recent]
                if not missing:
                    break
                time.sleep(0.05)
            time.sleep(linger_s)
        with self._lock:
            channels, self._channels = list(self._channels.values()), {}
        for ch in channels:
            ch.close()
        # the SDK's stop waits for its connections; one to a client that stopped reading (the front's pipe blocked
        # on it) would hold it for minutes: bounded, then the front's connections are closed, which releases it
        done = threading.Thread(target=self._server.stop, name="aerodaas-live-stop", daemon=True)
        done.start()
        done.join(self.STOP_WAIT_S)
        self._front.close()
        done.join(self.STOP_WAIT_S)

    def __enter__(self) -> "LiveServer":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()


class _SubscriptionWatch:
    """A ``foxglove.websocket.ServerListener``: sets ``event`` on the first subscription."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.subscriptions = 0

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self.subscriptions += 1
        self.event.set()

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        pass


def replay(path: str, address: str | None = None, *, speed: float = 1.0, wait_for_client_s: float | None = None,
           settle_s: float = 1.0, stop: threading.Event | None = None,
           on_ready: Callable[[LiveServer], None] | None = None, access: ServeAccess | None = None
           ) -> dict[str, Any]:
    """Serve the MCAP recording ``path`` live, ``speed`` times faster than it was recorded (1.0 = as recorded).

    Every channel of a finished file is advertised first; then, if ``wait_for_client_s`` is not None, playback
    waits (at most that many seconds; ``float('inf')`` = until it happens) for a client's first subscription, and
    ``settle_s`` more seconds for its other subscriptions (Foxglove subscribes panel by panel). Messages are then
    sent in log-time order (write order for an unfinished, crashed file, up to its last complete chunk) with their
    log-time spacing divided by ``speed``. ``access``: TLS and token (:func:`live_access`). ``on_ready(server)`` is
    called once the server listens. ``stop`` ends
    playback early. Returns ``{"url", "messages", "duration_s" (log time), "wall_s", "waited_s"}``.

    Raises ``FileNotFoundError``/``ValueError`` for a missing or non-MCAP file, ``ValueError`` for ``speed <= 0``
    and ``RuntimeError`` when the address cannot be bound.
    """
    if not (isinstance(speed, (int, float)) and math.isfinite(speed) and speed > 0):
        raise ValueError(f"--speed must be a positive number (1 = as recorded), got {speed!r}")
    stop = stop or threading.Event()
    f, finished = _open_mcap(path)
    watch = _SubscriptionWatch()
    with f:
        server = LiveServer(address, name=f"aerodaas replay {path}", listener=watch, time_capability=True,
                            access=access)
        try:
            if finished:
                summary = make_reader(f).get_summary()
                for ch in summary.channels.values():
                    sc = summary.schemas.get(ch.schema_id)
                    server.advertise(ch.topic, sc.name if sc else "", sc.encoding if sc else "", sc.data if sc else b"",
                                     ch.message_encoding)
                f.seek(0)
            if on_ready is not None:
                on_ready(server)
            t_wait = time.monotonic()
            if wait_for_client_s is not None:
                if watch.event.wait(None if math.isinf(wait_for_client_s) else wait_for_client_s):
                    stop.wait(settle_s)
            waited = time.monotonic() - t_wait
            n, t_first, t_last = 0, None, None
            wall0 = time.monotonic()
            for schema, channel, message in _iter_raw(f, None, finished):
                if stop.is_set():
                    break
                t = message.log_time
                if t_first is None:
                    t_first = t
                due = wall0 + (t - t_first) / 1e9 / speed
                lag = due - time.monotonic()
                if lag > 0 and stop.wait(lag):
                    break
                server.publish(RecordedMessage(channel.topic, schema.name if schema else "",
                                               schema.encoding if schema else "", schema.data if schema else b"",
                                               channel.message_encoding, t, message.data))
                if n % 50 == 0:
                    server.broadcast_time(t)
                n += 1
                t_last = t
            url = server.url
        finally:
            server.stop()
    return {"url": url, "messages": n, "duration_s": ((t_last - t_first) / 1e9) if n else 0.0,
            "wall_s": time.monotonic() - wall0, "waited_s": waited}
