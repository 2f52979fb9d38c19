"""The Tello SDK 2.0 wire formats we parse and build: state packets (:func:`parse_state`), the body-frame
``go x y z speed`` command (:func:`go_command`) and their limits (see the package docstring for the protocol)."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

__all__ = ["parse_state", "go_command", "DATAGRAM_SIZE", "GO_MIN_CM", "GO_MAX_CM", "GO_SPEED_CM",
           "REQUIRED_STATE_FIELDS"]


#: payload size of a full Tello video datagram; a shorter one ends a frame
DATAGRAM_SIZE = 1460
#: ``go``: each of x, y, z within -500..500 cm, not all three within -20..20 cm at once
GO_MIN_CM, GO_MAX_CM = 20, 500
#: ``go`` speed range, cm/s
GO_SPEED_CM = (10, 100)
#: the state fields a packet must carry for us to use it
REQUIRED_STATE_FIELDS = ("pitch", "roll", "yaw", "vgx", "vgy", "vgz", "h", "bat")


def parse_state(data: bytes | str) -> dict[str, float]:
    """Parse one Tello state datagram (``key:value;`` pairs, see the package docstring) into ``{key: float}``.

    Mission-pad attitude ``mpry`` (three comma-separated values) is skipped; every other value must be a finite
    number and the fields in :data:`REQUIRED_STATE_FIELDS` must be present. Raises ValueError naming the problem
    (not ASCII, a field without ``:``, a non-numeric value, missing fields)."""
    if isinstance(data, (bytes, bytearray)):
        try:
            text = bytes(data).decode("ascii")
        except UnicodeDecodeError:
            raise ValueError(f"state packet is not ASCII: {bytes(data)[:40]!r}") from None
    else:
        text = data
    text = text.strip()
    if not text:
        raise ValueError("empty state packet")
    out: dict[str, float] = {}
    for item in text.split(";"):
        item = item.strip()
        if not item:
            continue
        key, sep, val = item.partition(":")
        if not sep:
            raise ValueError(f"state field {item!r} has no ':'")
        key = key.strip()
        if key == "mpry":
            continue
        try:
            v = float(val)
        except ValueError:
            raise ValueError(f"state field {key!r}: value {val!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"state field {key!r}: value {val!r} is not finite")
        out[key] = v
    missing = [k for k in REQUIRED_STATE_FIELDS if k not in out]
    if missing:
        raise ValueError(f"state packet lacks fields {missing}: {text[:80]!r}")
    return out


def go_command(offset_enu: Sequence[float], yaw_enu_deg: float, speed_cm: int) -> str | None:
    """The SDK ``go x y z speed`` towards ``offset_enu`` (ENU metres from the vehicle) for a vehicle with ENU yaw
    ``yaw_enu_deg``: body frame x forward, y left, z up, in cm. An offset beyond 500 cm on some axis is scaled
    down along the same straight line (the first chunk of the leg). None when every axis is within the 20 cm the
    command cannot resolve (the SDK refuses x, y, z all within -20..20). ``speed_cm`` is clipped to 10..100 cm/s."""
    d = np.asarray(offset_enu, float)
    yaw = math.radians(yaw_enu_deg)
    fwd = d[0] * math.cos(yaw) + d[1] * math.sin(yaw)
    left = -d[0] * math.sin(yaw) + d[1] * math.cos(yaw)
    body = np.array([fwd, left, d[2]]) * 100.0
    peak = float(np.max(np.abs(body)))
    if peak <= GO_MIN_CM:
        return None
    x, y, z = (int(round(c)) for c in body * min(1.0, GO_MAX_CM / peak))
    if max(abs(x), abs(y), abs(z)) <= GO_MIN_CM:  # rounding brought it back into the dead zone
        return None
    return f"go {x} {y} {z} {int(np.clip(speed_cm, *GO_SPEED_CM))}"
