"""MAVLink 2 signing on the emulated vehicle (mavlink.io/en/guide/message_signing.html), as ArduPilot does it
(libraries/GCS_MAVLink/GCS_Signing.cpp): a key set at start or by SETUP_SIGNING, every packet out signed, every
packet in checked by pymavlink's parser (``MAVLink_signing``: signature, then the stream's timestamp) with only
RADIO_STATUS / RADIO accepted unsigned (GCS_Signing.cpp ``accept_unsigned_callback``). What the parser rejects becomes
BAD_DATA and never reaches a handler; :attr:`EmulatedSigning.rejected` counts it."""
from __future__ import annotations

import time
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

M = mavlink

#: messages accepted unsigned while signing is on (ArduPilot GCS_Signing.cpp ``accept_unsigned_callback``)
UNSIGNED_OK = frozenset({M.MAVLINK_MSG_ID_RADIO_STATUS, M.MAVLINK_MSG_ID_RADIO})
#: 1 January 2015 GMT in Unix seconds (the signing timestamp's epoch)
_EPOCH_S = 1420070400


def _now_timestamp() -> int:
    return int((max(time.time(), _EPOCH_S) - _EPOCH_S) * 100_000)


class EmulatedSigning:
    """The vehicle's signing state: :attr:`key` (32 bytes, None: signing off) and every link's parser/encoder set up
    with it (:meth:`setup`). ``key``: the initial key (None: off, as a vehicle never provisioned)."""

    def __init__(self, key: bytes | None = None) -> None:
        if key is not None and len(key) != 32:
            raise ValueError(f"signing key: 32 bytes, got {len(key)}")
        self.key = key
        self._mavs: list[Any] = []
        self._rejected_gone = 0  # rejected on links that are gone
        #: SETUP_SIGNING messages handled: (wall monotonic s, "set" / "disable")
        self.setups: list[tuple[float, str]] = []

    @property
    def enabled(self) -> bool:
        """A key is set: unsigned and wrongly signed packets are dropped."""
        return self.key is not None

    def accept_unsigned(self, mav: Any, msg_id: int) -> bool:
        """pymavlink's ``allow_unsigned_callback``: only :data:`UNSIGNED_OK` while signing is on."""
        return msg_id in UNSIGNED_OK

    def setup(self, mav: Any, timestamp: int = 0) -> None:
        """Give a link's ``mav`` (pymavlink ``MAVLink``) the current key (or none), signing from ``timestamp`` or
        the clock, whichever is later."""
        if mav not in self._mavs:
            self._mavs.append(mav)
        s = mav.signing
        if self.key is None:
            s.secret_key, s.sign_outgoing, s.allow_unsigned_callback = None, False, None
            return
        s.secret_key, s.sign_outgoing, s.link_id = self.key, True, 0
        s.allow_unsigned_callback = self.accept_unsigned
        s.timestamp = max(int(s.timestamp or 0), _now_timestamp(), int(timestamp))

    def forget(self, mav: Any) -> None:
        """A link closed: keep its rejected count."""
        if mav in self._mavs:
            self._rejected_gone += mav.signing.reject_count
            self._mavs.remove(mav)

    def on_setup_signing(self, msg: Any) -> None:
        """SETUP_SIGNING (it passed the check of the link it came on): the new key for every link, or signing off
        with an all-zero key and timestamp 0 (common.xml SETUP_SIGNING)."""
        key = bytes(msg.secret_key)
        if not any(key) and msg.initial_timestamp == 0:
            self.key = None
            self.setups.append((time.monotonic(), "disable"))
        else:
            self.key = key
            self.setups.append((time.monotonic(), "set"))
        for mav in self._mavs:
            self.setup(mav, msg.initial_timestamp)

    @property
    def rejected(self) -> int:
        """Packets the parsers dropped as unsigned or wrongly signed (pymavlink ``reject_count``), every link."""
        return self._rejected_gone + sum(m.signing.reject_count for m in self._mavs)
