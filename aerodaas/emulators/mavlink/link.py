"""The emulated vehicle's MAVLink link (:class:`EmulatorLink`): sockets (TCP server, UDP in/out), reading and
parsing, sending, STATUSTEXT chunking, and the link faults tests inject (:class:`LinkFaults`); MAVLink 2
serialisation by pymavlink. The vehicle's I/O thread (:meth:`MavlinkVehicleEmulator.start
<aerodaas.emulators.mavlink.vehicle.MavlinkVehicleEmulator.start>`) drives it."""
from __future__ import annotations

import ipaddress
import selectors
import socket
import time
from typing import Any, Literal

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.constants import _STATUSTEXT_LEN
from aerodaas.emulators.mavlink.signing import EmulatedSigning

M = mavlink


def parse_endpoint(address: str) -> tuple[str, str, int]:
    """``tcp:HOST:PORT`` / ``udpin:HOST:PORT`` / ``udpout:HOST:PORT`` -> (kind, host, port). Raises ValueError
    naming the address for anything else (port 0: any free port, for tcp and udpin)."""
    parts = address.split(":")
    if len(parts) != 3 or parts[0] not in ("tcp", "udpin", "udpout", "udp"):
        raise ValueError(f"--mavlink: expected tcp:HOST:PORT, udpin:HOST:PORT or udpout:HOST:PORT, got {address!r}")
    try:
        port = int(parts[2])
    except ValueError:
        raise ValueError(f"--mavlink: port must be an integer, got {parts[2]!r} in {address!r}") from None
    if not 0 <= port <= 65535:
        raise ValueError(f"--mavlink: port must be within 0-65535, got {port} in {address!r}")
    kind = "udpin" if parts[0] == "udp" else parts[0]
    return kind, parts[1], port


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class LinkFaults:
    """The link faults tests inject, shared by every peer of one vehicle: a cut link (:meth:`set_blackhole`) and
    single lost packets (:meth:`drop_next`). Read and changed under the vehicle's lock, except :attr:`blackhole`
    (see :attr:`EmulatorLink.blackholed`)."""

    def __init__(self) -> None:
        #: everything the vehicle sends is dropped
        self.blackhole = False
        #: everything the vehicle receives is dropped (logged in :attr:`blackholed_inbound`)
        self.blackhole_inbound = False
        self._drop_counts: dict[tuple[str, str], int] = {}  # (direction, message type) -> how many more to drop
        #: (direction "in"/"out", message type) of every message dropped by :meth:`drop_next`
        self.dropped: list[tuple[str, str]] = []
        #: (wall monotonic s, message type) of every message that arrived while the inbound link was cut
        self.blackholed_inbound: list[tuple[float, str]] = []

    def set_blackhole(self, on: bool, inbound: bool = True) -> None:
        """Cut (``on``) or restore the link: outbound always, inbound too with ``inbound``."""
        self.blackhole = bool(on)
        self.blackhole_inbound = bool(on and inbound)

    def drop_next(self, msg_type: str, direction: Literal["in", "out"] = "out", count: int = 1) -> None:
        """Lose the next ``count`` messages of type ``msg_type`` in ``direction``. Raises ValueError for another
        direction or count < 1."""
        if direction not in ("in", "out") or count < 1:
            raise ValueError(f"drop_next: direction must be 'in' or 'out' and count >= 1, got {direction!r}, {count!r}")
        key = (direction, msg_type.upper())
        self._drop_counts[key] = self._drop_counts.get(key, 0) + int(count)

    def dropping(self, direction: str, msg_type: str) -> bool:
        """Whether this ``msg_type`` message in ``direction`` is lost (one of the :meth:`drop_next` count used up
        and logged in :attr:`dropped`)."""
        key = (direction, msg_type)
        if self._drop_counts.get(key, 0) <= 0:
            return False
        self._drop_counts[key] -= 1
        self.dropped.append(key)
        return True


class _Link:
    """One peer: a TCP client, or a UDP peer address. Owns its MAVLink parser/encoder (sequence numbers) for
    ``system_id``/``component_id``, signed with ``signing``'s key when set; writes nothing while ``faults`` cut
    the link."""

    def __init__(self, faults: LinkFaults, signing: EmulatedSigning, system_id: int, component_id: int,
                 sock: socket.socket, addr: Any, tcp: bool) -> None:
        self.faults, self.sock, self.addr, self.tcp = faults, sock, addr, tcp
        self.mav = mavlink.MAVLink(self, srcSystem=system_id, srcComponent=component_id)
        self.mav.robust_parsing = True
        signing.setup(self.mav)  # MAVLink 2 signing, when the vehicle has a key (signing.py)
        self.outbuf = bytearray()
        self.closed = False

    def write(self, buf: bytes) -> None:  # called by MAVLink.send
        if self.faults.blackhole or self.closed:
            return
        if self.tcp:
            self.outbuf += buf
            if len(self.outbuf) > 4_000_000:  # a client that stopped reading
                self.closed = True
        else:
            try:
                self.sock.sendto(buf, self.addr)
            except OSError:
                pass

    def flush(self) -> None:
        if not self.tcp or not self.outbuf or self.closed:
            return
        try:
            n = self.sock.send(self.outbuf)
            del self.outbuf[:n]
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self.closed = True


class EmulatorLink:
    """The MAVLink link of one emulated vehicle (``system_id``/``component_id``, MAVLink 2, signed by
    ``signing`` once it has a key) to any number of peers: :meth:`open` binds the socket, :meth:`wait` and
    :meth:`receive` read what the peers sent (parsed, with the faults applied), :meth:`send` / :meth:`text` write,
    :meth:`flush` pushes TCP output and forgets closed peers, :meth:`close` closes everything. ``faults``: the
    injected link faults (:class:`LinkFaults`). Not thread-safe: the vehicle calls it under its lock (except
    :meth:`wait`)."""

    def __init__(self, system_id: int, component_id: int, signing: EmulatedSigning) -> None:
        self.system_id, self.component_id, self.signing = system_id, component_id, signing
        #: the vehicle's message encoder (messages are built with it and sent with each peer's own sequence)
        self.enc = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.faults = LinkFaults()
        #: the connected peers
        self.peers: list[_Link] = []
        self._udp_links: dict[Any, _Link] = {}
        self._sel: selectors.BaseSelector | None = None
        self._listen: socket.socket | None = None
        self._udp: socket.socket | None = None
        #: the address bound by :meth:`open` (None before)
        self.address: str | None = None
        #: every STATUSTEXT sent, in full
        self.statustexts: list[str] = []
        self._statustext_id = 0
        #: packets that did not parse (and BAD_DATA)
        self.bad_packets = 0

    def open(self, address: str, allow_remote: bool = False) -> str:
        """Listen (tcp, udpin) or send (udpout) on ``address``; returns the address actually bound (port 0 -> the
        chosen port). Raises ValueError for a non-loopback address unless ``allow_remote``, OSError when the port
        cannot be bound."""
        kind, host, port = parse_endpoint(address)
        if not allow_remote and not _is_loopback(host):
            raise ValueError(f"--mavlink: {host!r} is not a loopback address; the emulated vehicle accepts commands "
                             "from anyone who can reach it, so pass --allow-remote to expose it beyond this machine")
        self._sel = selectors.DefaultSelector()
        if kind == "tcp":
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind((host, port))
            s.listen(8)
            s.setblocking(False)
            self._listen = s
            self._sel.register(s, selectors.EVENT_READ, "accept")
            self.address = f"tcp:{host}:{s.getsockname()[1]}"
            return self.address
        u = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        udpout = None
        if kind == "udpin":
            u.bind((host, port))
            self.address = f"udpin:{host}:{u.getsockname()[1]}"
        else:
            u.bind(("127.0.0.1" if _is_loopback(host) else "0.0.0.0", 0))
            udpout = (host, port)
            self.address = f"udpout:{host}:{port}"
        u.setblocking(False)
        self._udp = u
        self._sel.register(u, selectors.EVENT_READ, "udp")
        if udpout:
            self._udp_link(udpout)
        return self.address

    def close(self) -> None:
        """Close every socket and forget the peers (idempotent)."""
        for link in list(self.peers):
            if link.tcp:
                try:
                    link.sock.close()
                except OSError:
                    pass
        self.peers.clear()
        self._udp_links.clear()
        for s in (self._listen, self._udp):
            if s is not None:
                try:
                    s.close()
                except OSError:
                    pass
        self._listen = self._udp = None
        if self._sel is not None:
            self._sel.close()
            self._sel = None

    @property
    def is_open(self) -> bool:
        """True between :meth:`open` and :meth:`close`."""
        return self._sel is not None

    def wait(self, timeout_s: float) -> list[selectors.SelectorKey] | None:
        """The sockets ready to read within ``timeout_s`` wall seconds, or None when the link is closed."""
        sel = self._sel
        if sel is None:
            return None
        try:
            return [key for key, _ in sel.select(timeout_s)]
        except (OSError, ValueError):
            return None

    def receive(self, ready: list[selectors.SelectorKey]) -> list[tuple[_Link, Any]]:
        """Accept, read and parse the ``ready`` sockets (:meth:`wait`): the (peer, message) pairs to handle, in
        order, without those the faults drop or that did not parse (counted in :attr:`bad_packets`)."""
        out: list[tuple[_Link, Any]] = []
        for key in ready:
            try:
                self._on_ready(key, out)
            except OSError:
                pass
        return out

    def flush(self) -> None:
        """Push each TCP peer's output; forget the peers whose socket closed."""
        for link in list(self.peers):
            link.flush()
            if link.closed:
                self._drop(link)

    def _udp_link(self, addr: Any) -> _Link:
        link = self._udp_links.get(addr)
        if link is None:
            link = _Link(self.faults, self.signing, self.system_id, self.component_id, self._udp, addr, tcp=False)
            self._udp_links[addr] = link
            self.peers.append(link)
        return link

    def _on_ready(self, key: selectors.SelectorKey, out: list[tuple[_Link, Any]]) -> None:
        if key.data == "accept":
            conn, addr = self._listen.accept()
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            link = _Link(self.faults, self.signing, self.system_id, self.component_id, conn, addr, tcp=True)
            self.peers.append(link)
            self._sel.register(conn, selectors.EVENT_READ, link)
        elif key.data == "udp":
            while True:
                try:
                    data, addr = self._udp.recvfrom(65535)
                except (BlockingIOError, InterruptedError):
                    return
                self._feed(self._udp_link(addr), data, out)
        else:
            link: _Link = key.data
            try:
                data = link.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                data = b""
            if not data:
                self._drop(link)
                return
            self._feed(link, data, out)

    def _drop(self, link: _Link) -> None:
        if link in self.peers:
            self.peers.remove(link)
            self.signing.forget(link.mav)
        if link.tcp:
            try:
                self._sel.unregister(link.sock)
            except (KeyError, ValueError):
                pass
            try:
                link.sock.close()
            except OSError:
                pass

    def _feed(self, link: _Link, data: bytes, out: list[tuple[_Link, Any]]) -> None:
        try:
            msgs = link.mav.parse_buffer(data) or []
        except Exception:  # a malformed stream must never stop the vehicle
            self.bad_packets += 1
            return
        faults = self.faults
        if faults.blackhole_inbound:  # out of range: parsed only to log what the ground station still sent
            now = time.monotonic()
            faults.blackholed_inbound.extend((now, m.get_type()) for m in msgs)
            return
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                self.bad_packets += 1
                continue
            if faults.dropping("in", msg.get_type()):
                continue
            out.append((link, msg))

    def send(self, msg: Any, link: _Link | None = None) -> None:
        """Send ``msg`` to ``link`` (None: every peer), each with its own sequence number; a message
        :meth:`LinkFaults.drop_next` loses still uses up its number."""
        links = [link] if link is not None else list(self.peers)
        if self.faults.dropping("out", msg.get_type()):
            for lk in links:  # lost on the way: it had its number
                lk.mav.seq = (lk.mav.seq + 1) % 256
            return
        for lk in links:
            try:
                lk.mav.send(msg)
            except Exception:  # noqa: BLE001
                lk.closed = True

    def inject(self, data: bytes | Any) -> None:
        """Put ``data`` on the link to every peer: raw bytes unchanged between two packets, a pymavlink message
        packed with each peer's sequence number."""
        for link in list(self.peers):
            if isinstance(data, (bytes, bytearray)):
                link.write(bytes(data))
            else:
                self.send(data, link)

    def text(self, severity: int, text: str) -> None:
        """STATUSTEXT: one message up to 50 characters (``id`` 0); longer ones in chunks of 50 with a shared
        non-zero ``id`` and ``chunk_seq`` 0, 1, ...; the last chunk is shorter than 50 (NUL-padded on the wire),
        an empty one when the text fills the previous chunks exactly (MAVLink 2 STATUSTEXT). Texts are cut at 200
        characters; each is logged in full in :attr:`statustexts`."""
        self.statustexts.append(text)
        data = text.encode("ascii", "replace")[:200]
        if len(data) <= _STATUSTEXT_LEN:
            self.send(self.enc.statustext_encode(severity, data, 0, 0))
            return
        self._statustext_id = self._statustext_id % 0xFFFF + 1
        chunks = [data[i:i + _STATUSTEXT_LEN] for i in range(0, len(data), _STATUSTEXT_LEN)]
        if len(chunks[-1]) == _STATUSTEXT_LEN:
            chunks.append(b"")
        for seq, chunk in enumerate(chunks):
            self.send(self.enc.statustext_encode(severity, chunk, self._statustext_id, seq))

    def for_us(self, msg: Any) -> bool:
        """Whether ``msg`` targets this vehicle (its system and component, or broadcast 0)."""
        ts = getattr(msg, "target_system", 0)
        tc = getattr(msg, "target_component", 0)
        return ts in (0, self.system_id) and tc in (0, self.component_id)
