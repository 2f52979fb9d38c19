"""The MAVLink link: sockets (TCP server, UDP in/out), the I/O loop, parsing, sending, STATUSTEXT chunking and the link-fault test hooks (MAVLink 2 serialisation by pymavlink)."""
from __future__ import annotations

import time
import selectors
import socket
import threading
import ipaddress
from typing import Any, Callable, Literal

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.constants import _STATUSTEXT_LEN


from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.vehicle import MavlinkVehicleEmulator

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


class _Link:
    """One peer: a TCP client, or a UDP peer address. Owns its MAVLink parser/encoder (sequence numbers)."""

    def __init__(self, emu: "MavlinkVehicleEmulator", sock: socket.socket, addr: Any, tcp: bool) -> None:
        self.emu, self.sock, self.addr, self.tcp = emu, sock, addr, tcp
        self.mav = mavlink.MAVLink(self, srcSystem=emu.system_id, srcComponent=emu.component_id)
        self.mav.robust_parsing = True
        emu.signing.setup(self.mav)  # MAVLink 2 signing, when the vehicle has a key (signing.py)
        self.outbuf = bytearray()
        self.closed = False

    def write(self, buf: bytes) -> None:  # called by MAVLink.send
        if self.emu.blackholed or self.closed:
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


class LinkMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator` (state lives there)."""

    def start(self, address: str = "tcp:127.0.0.1:0", allow_remote: bool = False) -> str:
        """Listen (tcp, udpin) or send (udpout) on ``address`` and start the vehicle thread. Returns the address
        actually bound (port 0 -> the chosen port). Raises ValueError for a non-loopback address unless
        ``allow_remote``, OSError when the port cannot be bound."""
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
        else:
            u = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            if kind == "udpin":
                u.bind((host, port))
                self.address = f"udpin:{host}:{u.getsockname()[1]}"
            else:
                u.bind(("127.0.0.1" if _is_loopback(host) else "0.0.0.0", 0))
                self._udpout_addr = (host, port)
                self.address = f"udpout:{host}:{port}"
            u.setblocking(False)
            self._udp = u
            self._sel.register(u, selectors.EVENT_READ, "udp")
            if self._udpout_addr:
                self._udp_link(self._udpout_addr)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"mavlink-{self.autopilot}-emulator", daemon=True)
        self._thread.start()
        return self.address

    def stop(self) -> None:
        """Stop the vehicle thread and close every socket (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        for link in list(self._links):
            if link.tcp:
                try:
                    link.sock.close()
                except OSError:
                    pass
        self._links.clear()
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

    def __enter__(self) -> "MavlinkVehicleEmulator":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    def set_blackhole(self, on: bool, inbound: bool = True) -> None:
        """Drop everything the vehicle sends (and, with ``inbound``, everything it receives, logging its type and
        wall time in :attr:`blackholed_inbound`), like a radio out of range; the vehicle keeps flying on its own.
        ``False`` restores the link."""
        with self._lock:
            self._blackhole = bool(on)
            self._blackhole_inbound = bool(on and inbound)

    @property
    def blackholed(self) -> bool:
        """True while :meth:`set_blackhole` drops everything the vehicle sends (read without the lock: a link
        write racing a switch sends or drops that one message, as a radio at the edge of its range)."""
        return self._blackhole

    def drop_next(self, msg_type: str, direction: Literal["in", "out"] = "out", count: int = 1) -> None:
        """Lose exactly the next ``count`` messages of type ``msg_type`` (e.g. ``"COMMAND_ACK"``,
        ``"MISSION_COUNT"``) that the vehicle sends (``"out"``) or receives (``"in"``), like single lost radio
        packets (a lost outgoing one used up its link's sequence number, as on a radio); each loss is logged in
        :attr:`dropped`. Raises ValueError for another direction or count < 1."""
        if direction not in ("in", "out") or count < 1:
            raise ValueError(f"drop_next: direction must be 'in' or 'out' and count >= 1, got {direction!r}, {count!r}")
        with self._lock:
            key = (direction, msg_type.upper())
            self._drop_counts[key] = self._drop_counts.get(key, 0) + int(count)

    def _dropping(self, direction: str, msg_type: str) -> bool:
        key = (direction, msg_type)
        if self._drop_counts.get(key, 0) <= 0:
            return False
        self._drop_counts[key] -= 1
        self.dropped.append(key)
        return True

    def inject(self, data: bytes | Any) -> None:
        """Put ``data`` on the link to every peer as if the vehicle had sent it: raw bytes (garbage, a corrupt
        frame) are written unchanged between two packets; a pymavlink message is packed with each link's
        sequence number."""
        with self._lock:
            for link in list(self._links):
                if isinstance(data, (bytes, bytearray)):
                    link.write(bytes(data))
                else:
                    self._send(data, link)

    def send_status_text(self, text: str, severity: int = M.MAV_SEVERITY_INFO) -> None:
        """Send STATUSTEXT ``text`` (ASCII) to every peer; longer than 50 characters it goes out in chunks as
        MAVLink 2 specifies (same non-zero ``id``, ``chunk_seq`` from 0, the last chunk NUL-terminated)."""
        with self._lock:
            self._text(severity, text)

    def _udp_link(self, addr: Any) -> _Link:
        link = self._udp_links.get(addr)
        if link is None:
            link = _Link(self, self._udp, addr, tcp=False)
            self._udp_links[addr] = link
            self._links.append(link)
        return link

    def _run(self) -> None:
        last = time.monotonic()
        while not self._stop.is_set():
            sel = self._sel
            if sel is None:
                break
            try:
                ready = sel.select(0.004)
            except (OSError, ValueError):
                break
            with self._lock:
                for key, _ in ready:
                    try:
                        self._on_ready(key)
                    except OSError:
                        pass
                now = time.monotonic()
                elapsed = min(now - last, 0.5) * self.speedup  # a stalled thread does not teleport the vehicle
                last = now
                while elapsed > 1e-9:
                    dt = min(self.physics_dt, elapsed)
                    elapsed -= dt
                    self._tick(dt)
                for link in list(self._links):
                    link.flush()
                    if link.closed:
                        self._drop(link)

    def _on_ready(self, key: selectors.SelectorKey) -> None:
        if key.data == "accept":
            conn, addr = self._listen.accept()
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            link = _Link(self, conn, addr, tcp=True)
            self._links.append(link)
            self._sel.register(conn, selectors.EVENT_READ, link)
        elif key.data == "udp":
            while True:
                try:
                    data, addr = self._udp.recvfrom(65535)
                except (BlockingIOError, InterruptedError):
                    return
                self._feed(self._udp_link(addr), data)
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
            self._feed(link, data)

    def _drop(self, link: _Link) -> None:
        if link in self._links:
            self._links.remove(link)
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

    def _feed(self, link: _Link, data: bytes) -> None:
        try:
            msgs = link.mav.parse_buffer(data) or []
        except Exception:  # a malformed stream must never stop the vehicle
            self.bad_packets += 1
            return
        if self._blackhole_inbound:  # out of range: parsed only to log what the ground station still sent
            now = time.monotonic()
            self.blackholed_inbound.extend((now, m.get_type()) for m in msgs)
            return
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                self.bad_packets += 1
                continue
            if self._drop_counts and self._dropping("in", msg.get_type()):
                continue
            try:
                self._handle(link, msg)
            except Exception as e:  # noqa: BLE001 - report, keep flying
                self._text(M.MAV_SEVERITY_ERROR, f"emulator: {msg.get_type()} handling failed: {e}")

    def _send(self, msg: Any, link: _Link | None = None) -> None:
        links = [link] if link is not None else list(self._links)
        if self._drop_counts and self._dropping("out", msg.get_type()):
            for lk in links:  # lost on the way: it had its number
                lk.mav.seq = (lk.mav.seq + 1) % 256
            return
        for lk in links:
            try:
                lk.mav.send(msg)
            except Exception:  # noqa: BLE001
                lk.closed = True

    def _text(self, severity: int, text: str) -> None:
        """STATUSTEXT: one message up to 50 characters (``id`` 0); longer ones in chunks of 50 with a shared
        non-zero ``id`` and ``chunk_seq`` 0, 1, ...; the last chunk is shorter than 50 (NUL-padded on the wire),
        an empty one when the text fills the previous chunks exactly. Texts are cut at 200 characters."""
        self.statustexts.append(text)
        data = text.encode("ascii", "replace")[:200]
        if len(data) <= _STATUSTEXT_LEN:
            self._send(self._enc.statustext_encode(severity, data, 0, 0))
            return
        self._statustext_id = self._statustext_id % 0xFFFF + 1
        chunks = [data[i:i + _STATUSTEXT_LEN] for i in range(0, len(data), _STATUSTEXT_LEN)]
        if len(chunks[-1]) == _STATUSTEXT_LEN:
            chunks.append(b"")
        for seq, chunk in enumerate(chunks):
            self._send(self._enc.statustext_encode(severity, chunk, self._statustext_id, seq))

    def _for_us(self, msg: Any) -> bool:
        ts = getattr(msg, "target_system", 0)
        tc = getattr(msg, "target_component", 0)
        return ts in (0, self.system_id) and tc in (0, self.component_id)

    def _handle(self, link: _Link, msg: Any) -> None:
        mtype = msg.get_type()
        if mtype == "SETUP_SIGNING":
            if self._for_us(msg):  # it passed this link's signature check (or signing is off)
                self.signing.on_setup_signing(msg)
            return
        handler: Callable | None = getattr(self, f"_on_{mtype.lower()}", None)
        if handler is None:
            return
        if mtype not in ("HEARTBEAT", "REQUEST_DATA_STREAM") and not self._for_us(msg):
            self._camera_command(link, msg)  # a camera component's, if one is attached (camera.py)
            return
        handler(link, msg)
