"""One MAVLink link, many vehicles: a connection is a shared object per endpoint inside a process.

Ground stations meet a fleet through one telemetry radio or one router port (MAVProxy ``--out``, mavlink-router):
every vehicle's messages arrive on one socket, told apart by the MAVLink header's system id and component id.
MAVLink routers forward by those ids (mavlink.io/en/guide/routing.html: a system learns which link each
``sysid/compid`` is reached on, and a message with a target goes only where that target was seen); MAVSDK's
``Mavsdk::add_any_connection`` opens a port once and discovers one ``System`` per system id seen on it
(``mavsdk_impl.cpp``: ``receive_message`` looks up the system by ``msg.sysid``, a new id makes a new ``System``).
This module does the same for :class:`~aerodaas.backends.mavlink.MavlinkBackend`:

- :func:`open_link` returns the :class:`SharedLink` of a connection string (one per :meth:`MavlinkConfig.link_key
  <aerodaas.config.MavlinkConfig.link_key>`; ``udpin:0.0.0.0:14600`` and ``udp:127.0.0.1:14600`` are one port),
  creating it on first use. It owns the pymavlink connection and one reader thread.
- Each robot gets a :class:`LinkPort` (the connection-like object its backend reads from and sends through):
  messages from the system id the robot claimed arrive in its own queue; GCS messages and other systems' traffic
  never reach it. Sends from every robot are serialised on the link's lock (one MAVLink sequence counter).
- :meth:`LinkPort.claim` waits for the autopilot HEARTBEAT of the robot's ``target_system``; ``"auto"`` takes the
  lowest system id seen on the link that no other robot has claimed (after one heartbeat period of discovery, so
  that the id order does not depend on which vehicle spoke first); ``None`` (unset) the first one heard. An id claimed twice in
  one process is refused (:class:`~aerodaas.backends.base.BackendError`); the configuration check refuses it before
  Ray starts (:meth:`aerodaas.config.EnvironmentConfig`).
- The link closes when its last port closes.
"""
from __future__ import annotations

import socket
import threading
import time
from collections import deque
from typing import Any, Callable

from pymavlink import mavutil

from aerodaas.backends.base import BackendError
from aerodaas.backends.mavlink._common import M, _NOT_VEHICLES, log
from aerodaas.process.state import PROCESS

#: wall seconds of discovery before ``target_system: auto`` picks the lowest unclaimed id (autopilots send their
#: HEARTBEAT at 1 Hz, mavlink.io/en/services/heartbeat.html)
DISCOVERY_S = 1.5
#: messages queued per robot; when full the oldest is dropped at once (counted in ``LinkPort.dropped``). The reader
#: never waits for one robot: it serves every vehicle on the link, and a wait for a slow robot (PX4's onboard link
#: streams HIGHRES_IMU, ATTITUDE_QUATERNION and ODOMETRY at 30-50 Hz each) starved the others, whose datagrams the
#: kernel then dropped (three PX4 behind one router port: robots 2 and 3 never saw SYS_STATUS or a COMMAND_ACK)
PORT_QUEUE = 5000
#: bytes of kernel receive buffer asked for a shared UDP socket (several vehicles' streams between two reads)
RCVBUF_BYTES = 4 * 1024 * 1024
#: messages kept per unclaimed system id (the latest), handed to the robot that claims it
PENDING = 200


def is_autopilot_heartbeat(msg: Any, source_system: int, source_component: int) -> bool:
    """A HEARTBEAT from a vehicle's autopilot: not ours, not a GCS/companion/peripheral (MAV_TYPE), not
    MAV_AUTOPILOT_INVALID."""
    if msg.get_srcSystem() == source_system and msg.get_srcComponent() == source_component:
        return False
    return msg.autopilot != M.MAV_AUTOPILOT_INVALID and msg.type not in _NOT_VEHICLES


class SharedLink:
    """One pymavlink connection shared by every robot of this process that names it (see the module docstring).

    ``key``: the endpoint (:meth:`MavlinkConfig.link_key`); ``conn``: the pymavlink connection; ``ports``: robot id
    -> :class:`LinkPort`; ``claimed``: system id -> robot id; ``seen``: system id -> (component id, HEARTBEAT,
    wall time first seen) of every autopilot heard on the link."""

    def __init__(self, key: str, conn: Any, source_system: int, source_component: int) -> None:
        self.key, self.conn = key, conn
        self.source = (source_system, source_component)
        self.ports: dict[str, LinkPort] = {}
        self.claimed: dict[int, str] = {}
        self.seen: dict[int, tuple[int, Any, float]] = {}
        self.send_lock = threading.Lock()
        #: the encoder every port sends through once a vehicle on the link signs (:meth:`use_signing_encoder`)
        self.tx: Any = None
        self.cond = threading.Condition()
        self.first_seen: float | None = None
        #: system id -> its latest messages while no robot has claimed it (handed to the robot that claims it)
        self.pending: dict[int, deque] = {}
        self.messages = 0
        self.unrouted = 0  # messages of a system id no robot claimed
        #: (system id, component id) -> [last sequence number, backward steps in a row] (:meth:`_count`)
        self._last_seq: dict[tuple[int, int], list[int]] = {}
        #: system id -> [messages received, messages lost] (:meth:`_count`; read with one ``dict.get``)
        self._totals: dict[int, list[int]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name=f"mavlink-link-{key}", daemon=True)
        self._thread.start()

    def use_signing_encoder(self) -> None:
        """From now on every port of this link sends through :attr:`tx`, a MAVLink 2 encoder of its own that parses
        nothing: signing sets the key of the vehicle each message is for on the encoder (signing.py
        ``LinkSigning.before_send``), and a key set on ``conn.mav`` would make pymavlink's parser (the reader
        thread's, with one key for every vehicle) check and reject the other vehicles' messages. One encoder for all
        ports: one sequence counter on the link. Idempotent."""
        with self.send_lock:
            if self.tx is None:
                self.tx = M.MAVLink(self.conn, srcSystem=self.source[0], srcComponent=self.source[1])

    def _read(self) -> None:
        conn = self.conn
        while not self._stop.is_set():
            t_read = time.monotonic()  # before the read: a mark never claims what a stall after the read missed
            try:
                msg = conn.recv_msg()
            except Exception:  # noqa: BLE001 - a broken packet or a socket hiccup: keep reading
                time.sleep(0.01)
                continue
            if msg is None:
                for port in list(self.ports.values()):
                    port.socket_idle(t_read)
                try:
                    conn.select(0.01)
                except Exception:  # noqa: BLE001
                    time.sleep(0.01)
                continue
            self.messages += 1
            try:
                sysid = msg.get_srcSystem()
            except Exception:  # noqa: BLE001 - BAD_DATA has no header
                continue
            self._count(msg, sysid)
            if msg.get_type() == "HEARTBEAT" and is_autopilot_heartbeat(msg, *self.source):
                with self.cond:
                    if sysid not in self.seen:
                        self.seen[sysid] = (msg.get_srcComponent(), msg, time.monotonic())
                        if self.first_seen is None:
                            self.first_seen = time.monotonic()
                        self.cond.notify_all()
                    else:
                        self.seen[sysid] = (self.seen[sysid][0], msg, self.seen[sysid][2])
            with self.cond:
                owner = self.claimed.get(sysid)
                port = self.ports.get(owner) if owner is not None else None
                if port is None:  # kept (the latest few) for a robot that claims this id soon
                    self.unrouted += 1
                    self.pending.setdefault(sysid, deque(maxlen=PENDING)).append(msg)
                    continue
            port.deliver(msg)

    def _count(self, msg: Any, sysid: int) -> None:
        """Count ``msg`` for its system id and the messages its sequence number says were lost before it. A MAVLink
        sender numbers its messages 0-255 per link, wrapping (MAVLink serialization, "SEQ": "used to detect packet
        loss"); a router forwards them unchanged, so a forward gap counts what was lost anywhere between the sender
        and this socket: the radio, the router, the kernel's buffer. A step back (a gap over 127: a repeat, or a
        message overtaken on the way, which its successor's gap already counted once) counts nothing and keeps the
        last number, until three in a row (the sender restarted) re-sync it. A loss of 256 or more in a row is
        invisible. Called by the reader thread only; never raises."""
        try:
            key, seq = (sysid, msg.get_srcComponent()), msg.get_seq()
        except Exception:  # noqa: BLE001 - BAD_DATA has no header
            return
        tot = self._totals.setdefault(sysid, [0, 0])
        tot[0] += 1
        st = self._last_seq.get(key)
        if st is None:
            self._last_seq[key] = [seq, 0]
            return
        gap = (seq - st[0] - 1) % 256
        if gap > 127:
            st[1] += 1
            if st[1] >= 3:
                st[:] = [seq, 0]
            return
        tot[1] += gap
        st[:] = [seq, 0]

    def counts(self, sysid: int) -> tuple[int, int]:
        """(messages received, messages lost by their sequence numbers) from every component of system ``sysid``
        since the link opened; (0, 0) for a system not heard. Safe from any thread; never raises."""
        tot = self._totals.get(sysid)
        return (tot[0], tot[1]) if tot is not None else (0, 0)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2)
        try:
            self.conn.close()
        except Exception:  # noqa: BLE001
            pass


class _SocketIdle:
    """A mark in a port's queue: the link's socket had nothing more to read at ``t`` (time.monotonic())."""

    __slots__ = ("t",)

    def __init__(self, t: float) -> None:
        self.t = t


class LinkPort:
    """One robot's view of a :class:`SharedLink`: what the backend's I/O thread reads (:meth:`recv_msg`,
    :meth:`select`) and sends through (:attr:`mav`, under :attr:`send_lock`). ``target_system`` /
    ``target_component``: the vehicle claimed (0 until :meth:`claim`).

    :attr:`live_since`: the latest wall time (time.monotonic()) at which the socket was found empty before the
    message :meth:`recv_msg` returned last, i.e. that message was received after then: after a stall of this
    process, a message with ``live_since`` later than the stall's end is no longer the backlog (offboard.py)."""

    def __init__(self, link: SharedLink, robot_id: str) -> None:
        self.link, self.robot_id = link, robot_id
        self.send_lock = link.send_lock
        self.target_system = self.target_component = 0
        self.dropped = 0
        self.live_since = 0.0
        #: the check every message of this robot's vehicle passes before it is queued (signing.py
        #: ``LinkSigning.accept``, set by a robot that signs): a rejected one is dropped at once, counted by the
        #: check, and never takes a queue slot, so a flood of unsigned messages in the vehicle's name cannot push
        #: the signed ones out of the queue (:data:`PORT_QUEUE`). None: every message is queued
        self.screen: Callable[[Any], bool] | None = None
        self._q: deque = deque()
        self._cv = threading.Condition()
        self._closed = False

    @property
    def mav(self) -> Any:
        """The link's encoder, looked up on every send: pymavlink replaces ``conn.mav`` when it switches to MAVLink 2
        on the first v2 byte it receives (``mavfile.auto_mavlink_version``); an encoder kept from before went on
        framing MAVLink 1, which drops every extension field (``mission_type``: a fence upload became a mission
        upload). Once a vehicle on the link signs, the link's own encoder (:meth:`SharedLink.use_signing_encoder`)."""
        tx = self.link.tx
        return tx if tx is not None else self.link.conn.mav

    def deliver(self, msg: Any) -> None:
        """Queue ``msg`` (a pymavlink message from this robot's vehicle) for :meth:`recv_msg`; called by the
        :class:`SharedLink`'s reader thread. A full queue (``PORT_QUEUE`` messages) drops its oldest message
        (counted in :attr:`dropped`); a message :attr:`screen` rejects is not queued. Never blocks, never raises."""
        screen = self.screen
        if screen is not None:
            try:
                if not screen(msg):
                    return
            except Exception:  # noqa: BLE001 - a message the check cannot read is not the vehicle's signed one
                return
        with self._cv:
            if len(self._q) >= PORT_QUEUE:
                self._q.popleft()
                self.dropped += 1
            self._q.append(msg)
            self._cv.notify_all()

    def socket_idle(self, t: float) -> None:
        """The link's reader found its socket empty at ``t``: mark the queue there (one mark between messages)."""
        with self._cv:
            if self._q and isinstance(self._q[-1], _SocketIdle):
                self._q[-1].t = t
            elif len(self._q) < PORT_QUEUE:
                self._q.append(_SocketIdle(t))

    def recv_msg(self) -> Any:
        """The next message of this robot's vehicle, or None (never blocks)."""
        with self._cv:
            while self._q:
                msg = self._q.popleft()
                if len(self._q) == PORT_QUEUE - 1:
                    self._cv.notify_all()  # the link's reader may be waiting for room
                if isinstance(msg, _SocketIdle):
                    self.live_since = msg.t
                    continue
                return msg
            return None

    @property
    def received(self) -> int:
        """Messages from this robot's vehicle (every component of its system id) that reached the link; 0 before
        :meth:`claim`. Never raises."""
        return self.link.counts(self.target_system)[0] if self.target_system else 0

    @property
    def lost(self) -> int:
        """Messages of this robot's vehicle lost before the link's socket, by their sequence numbers (a lower
        bound, :meth:`SharedLink._count`); 0 before :meth:`claim`. What this robot's own queue dropped is
        :attr:`dropped`. Never raises."""
        return self.link.counts(self.target_system)[1] if self.target_system else 0

    def select(self, timeout: float) -> bool:
        """Wait up to ``timeout`` wall seconds for a message; True when one is waiting."""
        with self._cv:
            if not self._q:
                self._cv.wait(timeout)
            return bool(self._q)

    def claim(self, target: int | str | None, deadline: float, tick: Callable[[], None] | None = None) -> Any:
        """Wait until the wanted vehicle's autopilot HEARTBEAT is seen on the link and make its system id this
        robot's; returns that HEARTBEAT. ``target``: a system id (1-255); ``"auto"``: the lowest unclaimed id seen
        after :data:`DISCOVERY_S` of discovery; ``None``: the first autopilot heard that no robot claimed (at once). ``tick`` is called about every 0.2 s while waiting
        (our GCS HEARTBEAT: a ``udpout`` vehicle learns our address from it). Raises BackendError when the id is
        claimed by another robot of this process, and TimeoutError at ``deadline`` (time.monotonic())."""
        link = self.link
        want = target if isinstance(target, int) else None
        while True:
            if tick is not None:
                tick()
            with link.cond:
                if want is not None and link.claimed.get(want, self.robot_id) != self.robot_id:
                    raise BackendError(f"robot {self.robot_id!r}: system id {want} on {link.key} is already flown by "
                                       f"robot {link.claimed[want]!r}; give each robot on one link its own "
                                       "mavlink.target_system")
                pick = None
                free = sorted((s for s in link.seen if s not in link.claimed), key=lambda s: link.seen[s][2])
                if want is not None and want in link.seen:
                    pick = want
                elif target is None and free:  # the first autopilot heard that nobody flies
                    pick = free[0]
                elif target == "auto" and free:  # the lowest id after a heartbeat period of discovery
                    settled = time.monotonic() - link.first_seen >= DISCOVERY_S
                    if settled or time.monotonic() >= deadline - 0.2:
                        pick = min(free)
                if pick is not None:
                    compid, hb, _ = link.seen[pick]
                    link.claimed[pick] = self.robot_id
                    self.target_system, self.target_component = pick, compid
                    for m in link.pending.pop(pick, ()):
                        self.deliver(m)
                    return hb
                if time.monotonic() >= deadline:
                    seen = sorted(link.seen)
                    raise TimeoutError(f"system ids seen on the link: {seen or 'none'}, claimed: "
                                       f"{ {s: r for s, r in sorted(link.claimed.items())} or 'none'}")
                link.cond.wait(0.2)

    def close(self) -> None:
        """Leave the link (idempotent); the last port to leave closes the socket."""
        with self._cv:
            if self._closed:
                return
            self._closed = True
            self._cv.notify_all()
        with PROCESS.mavlink_links.lock:
            link = self.link
            with link.cond:
                link.ports.pop(self.robot_id, None)
                for s in [s for s, r in link.claimed.items() if r == self.robot_id]:
                    del link.claimed[s]
            if not link.ports:
                PROCESS.mavlink_links.by_key.pop(link.key, None)
                link.close()


#: wall seconds between two reports of a :class:`ReportedCount`
REPORT_EVERY_S = 5.0


class ReportedCount:
    """A growing count (messages dropped, messages lost) reported at most every :data:`REPORT_EVERY_S` wall seconds:
    ``base`` is what the counter held when this connection began, :attr:`reported` what has been reported since."""

    __slots__ = ("base", "reported", "_next")

    def __init__(self, base: int = 0) -> None:
        self.base, self.reported, self._next = int(base), 0, 0.0

    def due(self, counter: int, now: float) -> int:
        """How many of ``counter`` (the counter's value now) are new since the last report, when a report is due at
        ``now`` (time.monotonic() seconds), and mark them reported; 0 when nothing new or not yet due."""
        new = counter - self.base - self.reported
        if new <= 0 or now < self._next:
            return 0
        self.reported += new
        self._next = now + REPORT_EVERY_S
        return new


class PortLosses:
    """The messages of one robot's vehicle that never reached its backend, counted from a connection on
    (:meth:`count_from`) and reported at most every :data:`REPORT_EVERY_S` wall seconds (:meth:`report`) as events
    (``event`` records a backend event) and warnings naming ``robot_id``."""

    def __init__(self, robot_id: str, event: Callable[..., None]) -> None:
        self.robot_id, self._event = robot_id, event
        self._drops, self._lost, self._received_base = ReportedCount(), ReportedCount(), 0

    def count_from(self, port: Any) -> None:
        """Count from now on: ``port`` (a :class:`LinkPort`; the shared link may have counted this system id for an
        earlier connection) has ``lost`` and ``received`` messages so far."""
        self._drops, self._lost = ReportedCount(), ReportedCount(port.lost)
        self._received_base = port.received

    def report(self, port: Any, now: float) -> None:
        """For ``port`` (the robot's :class:`LinkPort`, None when closed) at wall time ``now``: a
        ``link_messages_dropped`` event (and a warning) when the shared link's queue for this robot dropped messages
        since the last report (:data:`PORT_QUEUE`: this robot's I/O fell behind what its vehicle sends), at most
        every 5 wall seconds, with the count since the last report and in all; likewise ``link_messages_lost``
        (``lost`` since the last report, ``total``, ``received``, ``lost_pct``) for the messages the vehicle's
        MAVLink sequence numbers say never reached this process (radio, router, kernel buffer;
        :meth:`SharedLink._count`)."""
        rep = self._drops
        new = rep.due(int(getattr(port, "dropped", 0) or 0), now)
        if new:
            self._event("link_messages_dropped", dropped=new, total=rep.reported)
            log.warning("%s: the shared link dropped %d messages of this vehicle (%d in all): its I/O fell behind",
                        self.robot_id, new, rep.reported)
        rep = self._lost
        new = rep.due(int(getattr(port, "lost", 0) or 0), now)
        if new:
            lost, received = rep.reported, int(getattr(port, "received", 0) or 0) - self._received_base
            self._event("link_messages_lost", lost=new, total=lost, received=received,
                        lost_pct=round(100.0 * lost / max(1, lost + received), 2))
            log.warning("%s: %d messages of this vehicle were lost on the way here (%d of %d in all, by their "
                        "MAVLink sequence numbers)", self.robot_id, new, lost, lost + received)


def _grow_rcvbuf(conn: Any) -> None:
    """Ask the kernel for :data:`RCVBUF_BYTES` of receive buffer on a UDP link's socket (pymavlink's ``mavudp.port``;
    Linux caps it at ``net.core.rmem_max``): a router port carries several vehicles' streams, and datagrams that
    arrive while the buffer is full are dropped silently. Other link types are left alone."""
    sock = getattr(conn, "port", None)
    if isinstance(sock, socket.socket) and sock.type == socket.SOCK_DGRAM:
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
        except OSError:
            pass


def open_link(cfg: Any, robot_id: str, deadline: float) -> LinkPort:
    """The :class:`LinkPort` of robot ``robot_id`` on the link ``cfg.connection`` names (a
    :class:`~aerodaas.config.MavlinkConfig`), opening the connection when this process has none yet (retried until
    ``deadline``, time.monotonic(): a refused TCP connection, a serial device not there yet). Raises BackendError
    naming the connection when it cannot be opened, or when the robot already has a port on it."""
    key = cfg.link_key()
    last: Exception | None = None
    while True:
        with PROCESS.mavlink_links.lock:
            link = PROCESS.mavlink_links.by_key.get(key)
            if link is None:
                try:
                    conn = mavutil.mavlink_connection(
                        cfg.connection, baud=cfg.baud, source_system=cfg.source_system,
                        source_component=cfg.source_component, dialect="ardupilotmega", autoreconnect=True,
                        retries=0 if cfg.connection.startswith("tcp:") else 3)
                except Exception as e:  # noqa: BLE001 - refused, no such device: retry until the deadline
                    last = e
                    conn = None
                if conn is not None:
                    _grow_rcvbuf(conn)
                    link = SharedLink(key, conn, cfg.source_system, cfg.source_component)
                    PROCESS.mavlink_links.by_key[key] = link
            if link is not None:
                if robot_id in link.ports:
                    raise BackendError(f"robot {robot_id!r}: already connected on {key}")
                port = link.ports[robot_id] = LinkPort(link, robot_id)
                return port
        if time.monotonic() > deadline:
            raise BackendError(f"robot {robot_id!r}: mavlink connection {cfg.connection!r}: cannot open it: {last}")
        time.sleep(0.2)


def links() -> dict[str, SharedLink]:
    """The links open in this process (endpoint -> link), for reports and tests."""
    with PROCESS.mavlink_links.lock:
        return dict(PROCESS.mavlink_links.by_key)
