"""MAVLink 2 message signing (mavlink.io/en/guide/message_signing.html): the per-vehicle secret key read from a key
file, the signing timestamp kept beside it, the check of every incoming message and the signature of every outgoing
one. A concern object of :class:`~aerodaas.backends.mavlink.MavlinkBackend` (:class:`LinkSigning`), used by
:class:`~aerodaas.backends.mavlink.link.MavlinkLink`; :class:`NoSigning` stands in when ``mavlink.signing_key_file``
is unset.

The rules, from the specification ("Message Signing", sections Signature, Timestamp Handling, Accepting Signed
Packets, Accepting Incorrectly Signed Packets):

- signature = the first 48 bits of SHA-256(secret_key + header + payload + CRC + link id + timestamp);
- the timestamp counts 10 microsecond units since 1 January 2015 GMT, grows by at least one per message on a link,
  starts at the larger of the clock and the stored value, and is stored "at least once a minute": here every
  :data:`RESERVE` units *ahead* of its use, so that a process killed between two writes never re-uses one;
- a signed packet is accepted when its signature matches and its timestamp is later than the last one of its stream
  ``(system id, component id, link id)``; a new stream's first timestamp may be at most one minute older than ours;
- unsigned or wrongly signed packets are dropped, except those the receiver chooses to accept unsigned: here only
  RADIO_STATUS (a SiK radio's own report, which cannot sign; ArduPilot's ``accept_unsigned_callback`` in
  GCS_Signing.cpp lets it through for the same reason). Nothing that says where the vehicle is, its battery, mode or
  arming is ever taken unsigned.

pymavlink checks signatures with one key per parser (``MAVLink.check_signature``) and stores a stream's timestamp
before it checks the signature (a forged packet with a huge timestamp would then lock the real stream out); a shared
link carries several vehicles, each with its own key, so the check is made here, per vehicle, signature first."""
from __future__ import annotations

import enum
import hashlib
import hmac
import os
import re
import stat
import time
from pathlib import Path
from typing import Any, Callable

from aerodaas.backends.base import CredentialsRefused
from aerodaas.backends.mavlink._common import log

#: 1 January 2015 00:00:00 GMT in Unix seconds: the signing timestamp's epoch (spec, "Timestamp")
SIGNING_EPOCH_S = 1420070400
#: a new stream's first timestamp may be this much older than ours (10 us units: one minute; spec, "Accepting
#: Signed Packets")
NEW_STREAM_WINDOW = 6_000_000
#: the stored timestamp runs this far ahead of the one in use (10 us units: 10 s); rewritten when use catches up
RESERVE = 1_000_000
#: the link id our packets carry (spec, "Link IDs": one per link of the sender; one link per connection here)
LINK_ID = 0
#: messages accepted unsigned (spec, "Accepting Incorrectly Signed Packets"): a radio's own link report only
ALLOWED_UNSIGNED = frozenset({"RADIO_STATUS"})
#: rejected messages reported one event each, per kind (``link_unsigned`` / ``link_bad_signature``); then summaries
FIRST_EVENTS = 5
#: wall seconds between two summary events of one kind
SUMMARY_EVERY_S = 5.0
#: the SETUP_SIGNING key that switches signing off (MAVLink common.xml SETUP_SIGNING: "all zero ... disable")
DISABLE_KEY = bytes(32)

#: the attribute set on a pymavlink message once :meth:`LinkSigning.accept` took it (a local mark, never on the wire)
ACCEPTED_MARK = "_aerodaas_signature_accepted"

_HEX_KEY = re.compile(r"[0-9a-fA-F]{64}")


class KeyFileError(ValueError):
    """A signing key file that cannot be used (missing, readable by group or others, not a key)."""


def now_timestamp() -> int:
    """The signing clock now: 10 microsecond units since :data:`SIGNING_EPOCH_S` (spec, "Timestamp")."""
    return int((max(time.time(), SIGNING_EPOCH_S) - SIGNING_EPOCH_S) * 100_000)


def read_key_file(path: str | os.PathLike) -> bytes:
    """The 32-byte secret key in the file at ``path``: 64 hexadecimal characters (one line, as ``openssl rand -hex
    32`` writes it; surrounding whitespace ignored) or exactly 32 raw bytes. Raises :class:`KeyFileError` (never
    quoting the file's content) when the file is missing, not a regular file, readable or writable by group or
    others (mode & 0o077), or neither form."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError as e:
        raise KeyFileError(f"key file {str(p)!r} cannot be read: {e.strerror or e}") from None
    if not stat.S_ISREG(st.st_mode):
        raise KeyFileError(f"key file {str(p)!r} is not a regular file")
    if st.st_mode & 0o077:
        raise KeyFileError(f"key file {str(p)!r} has mode {stat.S_IMODE(st.st_mode):04o}: group or others may read "
                           f"it; make it private (chmod 600 {p})")
    try:
        data = p.read_bytes()
    except OSError as e:
        raise KeyFileError(f"key file {str(p)!r} cannot be read: {e.strerror or e}") from None
    if len(data) == 32:
        return data
    text = data.strip()
    if len(text) == 64 and _HEX_KEY.fullmatch(text.decode("ascii", "replace")):
        return bytes.fromhex(text.decode("ascii"))
    raise KeyFileError(f"key file {str(p)!r} holds {len(data)} bytes: a signing key is 32 raw bytes or 64 "
                       "hexadecimal characters (openssl rand -hex 32)")


def write_key_file(path: str | os.PathLike, key: bytes) -> None:
    """Write ``key`` (32 bytes) as one line of 64 hexadecimal characters to a new private file (mode 0600) at
    ``path``. Raises FileExistsError when the file exists, ValueError for a key that is not 32 bytes."""
    if len(key) != 32:
        raise ValueError(f"a signing key is 32 bytes, got {len(key)}")
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(key.hex() + "\n")


class TimestampStore:
    """The signing timestamp of the links one key signs, in a small private file beside the key file
    (``<key file>.timestamp``, mode 0600, one decimal number of 10 us units). One value for every link the key is
    used on: a single clock that never goes back satisfies each link's "monotonically increasing" rule."""

    def __init__(self, key_path: str | os.PathLike) -> None:
        self.path = Path(str(key_path) + ".timestamp")

    def load(self) -> int:
        """The stored timestamp, 0 when there is none yet. Raises :class:`KeyFileError` for a file that is not a
        number or is readable by group or others."""
        try:
            st = self.path.stat()
        except FileNotFoundError:
            return 0
        if st.st_mode & 0o077:
            raise KeyFileError(f"signing timestamp file {str(self.path)!r} has mode {stat.S_IMODE(st.st_mode):04o}; "
                               f"make it private (chmod 600 {self.path})")
        text = self.path.read_text().strip()
        if not text.isdigit():
            raise KeyFileError(f"signing timestamp file {str(self.path)!r} does not hold a number")
        return int(text)

    def save(self, value: int) -> None:
        """Store ``value`` (written to a private temporary file, flushed to disk, then renamed over the old one: a
        crash leaves the old value or the new one). Raises OSError."""
        tmp = self.path.with_name(self.path.name + ".tmp")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(f"{int(value)}\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.path)


class Verdict(enum.Enum):
    """What the signature check says of one incoming message."""

    SIGNED = "signed"  # correctly signed, timestamp new
    ALLOWED_UNSIGNED = "allowed_unsigned"  # unsigned, of a type the spec lets through (ALLOWED_UNSIGNED)
    UNSIGNED = "unsigned"
    BAD_SIGNATURE = "bad_signature"
    REPLAYED = "replayed"  # correctly signed, but its timestamp is not newer than its stream's (or too old)


def sign_outgoing(mav: Any, key: bytes, timestamp: int, link_id: int = LINK_ID) -> None:
    """Make pymavlink's encoder ``mav`` (a ``MAVLink`` object) sign every message it sends from now on with ``key``
    (32 bytes), link id ``link_id``, from ``timestamp`` (10 us units since :data:`SIGNING_EPOCH_S`) or the
    timestamp it already holds, whichever is later: pymavlink then adds one per message (spec, "Timestamp
    Handling"). The one place our senders set up pymavlink's signing (:meth:`LinkSigning.before_send`, through
    which the backend, ``aerodaas mission`` and ``aerodaas mavlink signing`` send). Raises ValueError for a key
    that is not 32 bytes."""
    if len(key) != 32:
        raise ValueError(f"a signing key is 32 bytes, got {len(key)}")
    s = mav.signing
    s.secret_key, s.link_id, s.sign_outgoing = bytes(key), int(link_id), True
    s.timestamp = max(int(s.timestamp or 0), int(timestamp))


def sign_fields(buf: bytes | bytearray) -> tuple[bool, int, int]:
    """(signed, link id, timestamp) of a packet ``buf`` as received (pymavlink ``get_msgbuf()``): a MAVLink 2
    packet (0xFD) whose incompatibility flags have MAVLINK_IFLAG_SIGNED (0x01) ends in the 13-byte signature
    block (link id, 48-bit little-endian timestamp, 48-bit signature; spec, "Frame Format")."""
    if len(buf) < 12 + 13 or buf[0] != 0xFD or not buf[2] & 0x01:
        return False, 0, 0
    return True, buf[-13], int.from_bytes(bytes(buf[-12:-6]), "little")


class SignatureCheck:
    """The receiving half of signing for one key: each stream's last accepted timestamp (a stream is ``(system id,
    component id, link id)``) and the check of :meth:`verdict`."""

    def __init__(self, key: bytes) -> None:
        self._key = bytes(key)
        self._streams: dict[tuple[int, int, int], int] = {}
        #: the latest timestamp accepted (our next ones must not be older: spec, "Timestamp Handling")
        self.latest = 0

    def verdict(self, msg: Any, local: int) -> Verdict:
        """Check ``msg`` (a pymavlink message with its packet, ``get_msgbuf()``) against the key; ``local``: our
        signing clock now (:func:`now_timestamp`). The signature is checked before the timestamp, and only an
        accepted message moves its stream's timestamp on."""
        buf = msg.get_msgbuf()
        signed, link_id, ts = sign_fields(buf)
        if not signed:
            return Verdict.ALLOWED_UNSIGNED if msg.get_type() in ALLOWED_UNSIGNED else Verdict.UNSIGNED
        want = hashlib.sha256(self._key + bytes(buf[:-6])).digest()[:6]
        if not hmac.compare_digest(want, bytes(buf[-6:])):
            return Verdict.BAD_SIGNATURE
        stream = (msg.get_srcSystem(), msg.get_srcComponent(), link_id)
        last = self._streams.get(stream)
        if (last is not None and ts <= last) or (last is None and ts + NEW_STREAM_WINDOW < local):
            return Verdict.REPLAYED
        self._streams[stream] = ts
        self.latest = max(self.latest, ts)
        return Verdict.SIGNED


class RejectReport:
    """Rejected incoming messages of one kind (event ``name``: ``link_unsigned`` or ``link_bad_signature``): the
    first :data:`FIRST_EVENTS` each as an event (message type, system, component, reason), then a summary event at
    most every :data:`SUMMARY_EVERY_S` wall seconds (``dropped`` since the last one, ``total``), and warnings naming
    ``robot_id``. ``event`` records a backend event."""

    def __init__(self, name: str, robot_id: str, event: Callable[..., None]) -> None:
        self.name, self.robot_id, self._event = name, robot_id, event
        self.total = 0
        self._reported = 0
        self._next = 0.0

    def reject(self, msg: Any, reason: Verdict) -> None:
        """Count ``msg`` (dropped for ``reason``); one event for each of the first :data:`FIRST_EVENTS`."""
        self.total += 1
        if self.total <= FIRST_EVENTS:
            self._reported = self.total
            self._event(self.name, message=msg.get_type(), system=msg.get_srcSystem(),
                        component=msg.get_srcComponent(), reason=reason.value, total=self.total)
            log.warning("%s: dropped a %s %s from system %d component %d", self.robot_id, reason.value,
                        msg.get_type(), msg.get_srcSystem(), msg.get_srcComponent())

    def report(self, now: float, force: bool = False) -> None:
        """A summary event when messages were dropped since the last report and one is due at wall time ``now``
        (``force``: due now)."""
        new = self.total - self._reported
        if new <= 0 or (now < self._next and not force):
            return
        self._reported, self._next = self.total, now + SUMMARY_EVERY_S
        self._event(self.name, dropped=new, total=self.total)
        log.warning("%s: dropped %d more %s messages (%d in all)", self.robot_id, new, self.name, self.total)


class NoSigning:
    """Signing off (``mavlink.signing_key_file`` unset): every message is taken, ours go out unsigned, and the
    connection says so (:meth:`announce`). ``robot_id``: named in the warning; ``event``: records a backend event
    (None: none recorded)."""

    enabled = False
    unsigned = bad_signature = 0
    screen = None  # shared_link.py LinkPort.screen: every message is queued

    def __init__(self, robot_id: str = "", event: Callable[..., None] | None = None) -> None:
        self.robot_id, self._event = robot_id, event

    def announce(self, connection: str) -> None:
        """The link on ``connection`` is up unsigned: a ``link_not_signed`` event (the run summary repeats it:
        runtime/report.py) and a warning, for anyone who can put a packet on the link can command the vehicle."""
        if self._event is not None:
            self._event("link_not_signed", connection=connection)
        log.warning("%s: the MAVLink link %s is not signed (mavlink.signing_key_file unset): anyone who can put a "
                    "packet on it can command the vehicle or speak in its name", self.robot_id, connection)

    def accept(self, msg: Any) -> bool:
        """Every message is taken."""
        return True

    def before_send(self, mav: Any) -> None:
        """Ours go out unsigned (the link's encoder may be shared with a vehicle that signs: shared_link.py)."""
        mav.signing.sign_outgoing = False

    def after_send(self, mav: Any) -> None:
        """Nothing to keep."""

    def report(self, now: float, force: bool = False) -> None:
        """Nothing to report."""

    def close(self) -> None:
        """Nothing to store."""


class LinkSigning:
    """Signing on (``mavlink.signing_key_file``) for one vehicle: its key (:func:`read_key_file`), the timestamp
    store beside it (:class:`TimestampStore`), the check of every message from it (:meth:`accept`) and the signature
    of every message to it (:meth:`before_send` / :meth:`after_send`, called under the link's send lock around the
    send). Rejected messages are counted in :attr:`unsigned` / :attr:`bad_signature` (wrong signature or replayed
    timestamp) and reported as ``link_unsigned`` / ``link_bad_signature`` events (:class:`RejectReport`).

    ``key_path``: the key file; ``robot_id``: named in reports; ``event``: records a backend event. Raises
    :class:`KeyFileError` for a key or timestamp file that cannot be used, OSError when the timestamp cannot be
    stored."""

    enabled = True

    def __init__(self, key_path: str, robot_id: str, event: Callable[..., None]) -> None:
        self.key_path = str(key_path)
        self._key = read_key_file(key_path)
        self._check = SignatureCheck(self._key)
        self._store = TimestampStore(key_path)
        #: the first timestamp we may use: the larger of the clock and the stored value (spec, "Timestamp Handling")
        self._floor = max(now_timestamp(), self._store.load())
        self._reserved = self._floor + RESERVE
        self._store.save(self._reserved)  # before the first send: a crash right after it never re-uses one
        self._unsigned = RejectReport("link_unsigned", robot_id, event)
        self._bad = RejectReport("link_bad_signature", robot_id, event)

    @property
    def unsigned(self) -> int:
        """Unsigned messages dropped (not of :data:`ALLOWED_UNSIGNED`)."""
        return self._unsigned.total

    @property
    def bad_signature(self) -> int:
        """Messages dropped for a wrong signature or a replayed (old) timestamp."""
        return self._bad.total

    def accept(self, msg: Any) -> bool:
        """True when ``msg`` (from the vehicle's system) is correctly signed with a new timestamp, or is of a type
        allowed unsigned; otherwise it is counted, reported and False. A message accepted once is marked
        (:data:`ACCEPTED_MARK`) and accepted again at once: the shared link's reader checks each message before it
        is queued (shared_link.py ``LinkPort.screen``: a rejected one is dropped there, so a flood of them never
        takes a queue slot of a signed one), and the I/O thread's dispatch checks what reaches it by any path.
        Called by one thread at a time (the link's reader, or the caller of connect before the reader routes)."""
        if getattr(msg, ACCEPTED_MARK, False):
            return True
        verdict = self._check.verdict(msg, now_timestamp())
        if verdict in (Verdict.SIGNED, Verdict.ALLOWED_UNSIGNED):
            setattr(msg, ACCEPTED_MARK, True)
            return True
        (self._unsigned if verdict is Verdict.UNSIGNED else self._bad).reject(msg, verdict)
        return False

    def screen(self, msg: Any) -> bool:
        """The shared link's check of a message of this vehicle before it is queued (shared_link.py
        ``LinkPort.screen``): :meth:`accept`; malformed and unknown messages pass (the link's dispatch counts and
        skips them)."""
        mtype = msg.get_type()
        return mtype == "BAD_DATA" or mtype.startswith("UNKNOWN_") or self.accept(msg)

    def announce(self, connection: str) -> None:
        """Nothing to say: the link is signed (a vehicle without the key never got this far)."""

    def before_send(self, mav: Any) -> None:
        """Make ``mav`` (a pymavlink ``MAVLink`` encoder that parses nothing: shared_link.py ``SharedLink.tx``)
        sign the next messages with this vehicle's key, from a timestamp no older than the clock, the stored value
        or any timestamp accepted from the vehicle. Caller holds the link's send lock."""
        sign_outgoing(mav, self._key, max(now_timestamp(), self._floor, self._check.latest))

    def after_send(self, mav: Any) -> None:
        """Keep the timestamp ``mav`` will use next; store a new reserve once use reached the stored one. Caller
        holds the link's send lock. Raises OSError when the store cannot be written."""
        self._floor = ts = int(mav.signing.timestamp)
        if ts >= self._reserved:
            self._reserved = ts + RESERVE
            self._store.save(self._reserved)

    def report(self, now: float, force: bool = False) -> None:
        """Summary events of the messages dropped (:class:`RejectReport`), when due at wall time ``now``."""
        self._unsigned.report(now, force)
        self._bad.report(now, force)

    def close(self) -> None:
        """Report what is not reported yet and store the timestamp in use (never raises)."""
        self.report(time.monotonic(), force=True)
        try:
            self._store.save(max(self._reserved, self._floor + 1))
        except OSError as e:
            log.warning("signing timestamp not stored in %s: %s", self._store.path, e)


def make_signing(key_path: str | None, robot_id: str, event: Callable[..., None]) -> LinkSigning | NoSigning:
    """:class:`LinkSigning` for the key file ``key_path`` (``mavlink.signing_key_file``), :class:`NoSigning` when
    None. Raises what :class:`LinkSigning` raises."""
    return NoSigning(robot_id, event) if key_path is None else LinkSigning(key_path, robot_id, event)


class SignedOnly:
    """``mavlink.require_signing``: a command that moves the vehicle (arming, take-off, a target, a mission start)
    goes only over a signed link. Stopping (hold, land, RTL, disarm, the safe end) is never refused: refusing it
    could only leave a vehicle flying. Asked by the concerns that send such commands (:class:`VehicleAction`,
    :class:`OffboardControl`, :class:`AutopilotMission`) before they send anything.

    ``settings``: the robot's :class:`~aerodaas.config.MavlinkConfig` (``require_signing``, ``connection``,
    ``signing_key_file``); ``signing``: the link's :class:`LinkSigning` / :class:`NoSigning`; ``link``: the
    :class:`~aerodaas.backends.mavlink.link.MavlinkLink` (its ``port`` is None until connected)."""

    def __init__(self, robot_id: str, settings: Any, *, signing: LinkSigning | NoSigning, link: Any) -> None:
        self.robot_id, self._settings, self._signing, self._link = robot_id, settings, signing, link

    def require(self, command: str) -> None:
        """Raises :class:`~aerodaas.backends.base.CredentialsRefused` naming the robot, ``command`` and the link
        when ``mavlink.require_signing`` is set and the link is not signed; nothing was sent then."""
        s = self._settings
        if s.require_signing and not (self._signing.enabled and self._link.port is not None):
            raise CredentialsRefused(
                f"robot {self.robot_id!r}: {command} refused: mavlink.require_signing is true but the link "
                f"{s.connection!r} is not signed (mavlink.signing_key_file "
                f"{'unset' if s.signing_key_file is None else 'set, but not connected'}); nothing was sent")
