"""The emulated firmware's parameters and the parameter protocol (PARAM_REQUEST_LIST / PARAM_REQUEST_READ /
PARAM_SET -> PARAM_VALUE; mavlink.io/en/services/parameter.html)."""
from __future__ import annotations

import math
import struct
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.flavour import PX4_INT_PARAMS, SPEED_PARAMS
from aerodaas.emulators.mavlink.link import EmulatorLink
from aerodaas.emulators.mavlink.motion import Motion

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link

M = mavlink


class EmulatedParams:
    """The parameter table of the emulated ``autopilot`` (``values``: name -> value in the firmware's units, kept
    as this very dict, in the order the protocol indexes it) and the parameter protocol's messages, built with the
    vehicle's encoder ``enc``. It decides what to answer; :class:`ParamProtocol` sends and stores.
    PX4 sends and expects its integer parameters (:data:`.flavour.PX4_INT_PARAMS`) bytewise as INT32."""

    def __init__(self, values: dict[str, float], autopilot: str, enc: Any) -> None:
        self.values, self.autopilot, self._enc = values, autopilot, enc
        self.px4 = autopilot == "px4"

    def message(self, name: str) -> Any:
        """PARAM_VALUE of parameter ``name`` (REAL32, or PX4's INT32 bytewise), with its index and the count."""
        names = list(self.values)
        if self.px4 and name in PX4_INT_PARAMS:  # bytewise INT32, as PX4 sends its integers
            value = struct.unpack("<f", struct.pack("<i", int(self.values[name])))[0]
            return self._enc.param_value_encode(name.encode(), value, M.MAV_PARAM_TYPE_INT32, len(names),
                                                names.index(name))
        return self._enc.param_value_encode(name.encode(), float(self.values[name]), M.MAV_PARAM_TYPE_REAL32,
                                            len(names), names.index(name))

    def list_reply(self) -> list[Any]:
        """PARAM_REQUEST_LIST: a PARAM_VALUE of every parameter, in index order."""
        return [self.message(name) for name in self.values]

    def read_reply(self, msg: Any) -> list[Any]:
        """PARAM_REQUEST_READ ``msg`` (by name, or by index when ``param_index`` >= 0): that parameter's
        PARAM_VALUE, none for an unknown name or an index out of range."""
        names = list(self.values)
        idx = msg.param_index
        name = msg.param_id if idx < 0 else (names[idx] if idx < len(names) else "")
        if isinstance(name, bytes):
            name = name.decode(errors="replace")
        name = name.rstrip("\x00")
        return [self.message(name)] if name in self.values else []

    def decode_set(self, msg: Any) -> tuple[str, float] | None:
        """PARAM_SET ``msg`` -> (name, value) to store, or None when the firmware ignores it: an unknown name gets
        no answer, PX4 refuses a type other than the parameter's ("param types mismatch"), and a non-finite value is
        not stored. A stored parameter's new value is broadcast as PARAM_VALUE (both firmware do, trace)."""
        name = msg.param_id.decode(errors="replace") if isinstance(msg.param_id, bytes) else msg.param_id
        name = name.rstrip("\x00")
        if name not in self.values:
            return None
        value = float(msg.param_value)
        if self.px4 and (name in PX4_INT_PARAMS) != (msg.param_type == M.MAV_PARAM_TYPE_INT32):
            return None  # PX4: "param types mismatch", nothing set, no PARAM_VALUE
        if self.px4 and name in PX4_INT_PARAMS:
            value = float(struct.unpack("<i", struct.pack("<f", msg.param_value))[0])
        return (name, value) if math.isfinite(value) else None


class ParamProtocol:
    """The parameter protocol's handlers: the answers of ``table`` (:class:`EmulatedParams`) sent on ``link``;
    a stored speed parameter changes the vehicle's speeds at once through ``motion``. Not locked: the vehicle calls
    it under its lock."""

    def __init__(self, table: EmulatedParams, link: EmulatorLink, motion: Motion) -> None:
        self.table, self.link, self.motion = table, link, motion

    def store(self, name: str, value: float) -> None:
        """Store parameter ``name`` (firmware units); a speed parameter changes the vehicle's speeds at once."""
        self.table.values[name] = value
        if name in SPEED_PARAMS:
            self.motion.apply_speed_params()

    def on_param_request_list(self, link: _Link, msg: Any) -> None:
        """PARAM_REQUEST_LIST: every PARAM_VALUE to the asking ``link``."""
        for out in self.table.list_reply():
            self.link.send(out, link)

    def on_param_request_read(self, link: _Link, msg: Any) -> None:
        """PARAM_REQUEST_READ: the parameter's PARAM_VALUE to the asking ``link`` (nothing for an unknown one)."""
        for out in self.table.read_reply(msg):
            self.link.send(out, link)

    def on_param_set(self, link: _Link, msg: Any) -> None:
        """PARAM_SET: stored (:meth:`store`) and its PARAM_VALUE broadcast to every link, as the firmware does."""
        got = self.table.decode_set(msg)
        if got is not None:
            self.store(*got)
            self.link.send(self.table.message(got[0]))  # to every link, as the firmware broadcasts it
