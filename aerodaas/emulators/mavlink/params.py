"""The parameter protocol (PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET -> PARAM_VALUE; mavlink.io/en/services/parameter.html)."""
from __future__ import annotations

import math
import struct
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink



from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link

from aerodaas.emulators.mavlink.flavour import PX4_INT_PARAMS, SPEED_PARAMS

M = mavlink


class ParamMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator` (state lives there)."""

    def set_param(self, name: str, value: float) -> None:
        """Set an emulated parameter (see the class docstring). Raises KeyError for an unknown name."""
        with self._lock:
            if name not in self.params:
                raise KeyError(f"unknown {self.autopilot} parameter {name!r}")
            self._store_param(name, float(value))

    def _store_param(self, name: str, value: float) -> None:
        self.params[name] = value
        if name in SPEED_PARAMS:
            self._apply_speed_params()

    def _param_msg(self, name: str) -> Any:
        names = list(self.params)
        if self.px4 and name in PX4_INT_PARAMS:  # bytewise INT32, as PX4 sends its integers
            value = struct.unpack("<f", struct.pack("<i", int(self.params[name])))[0]
            return self._enc.param_value_encode(name.encode(), value, M.MAV_PARAM_TYPE_INT32, len(names),
                                                names.index(name))
        return self._enc.param_value_encode(name.encode(), float(self.params[name]), M.MAV_PARAM_TYPE_REAL32,
                                            len(names), names.index(name))

    def _on_param_request_list(self, link: _Link, msg: Any) -> None:
        for name in self.params:
            self._send(self._param_msg(name), link)

    def _on_param_request_read(self, link: _Link, msg: Any) -> None:
        names = list(self.params)
        name = msg.param_id if msg.param_index < 0 else (names[msg.param_index] if msg.param_index < len(names) else "")
        if isinstance(name, bytes):
            name = name.decode(errors="replace")
        name = name.rstrip("\x00")
        if name in self.params:
            self._send(self._param_msg(name), link)

    def _on_param_set(self, link: _Link, msg: Any) -> None:
        name = msg.param_id.decode(errors="replace") if isinstance(msg.param_id, bytes) else msg.param_id
        name = name.rstrip("\x00")
        # the parameter protocol: an unknown name gets no answer; a known one is stored and its new value
        # broadcast as PARAM_VALUE (REAL32, the firmware's units) - both firmware do so (trace)
        if name not in self.params:
            return
        value = float(msg.param_value)
        if self.px4 and (name in PX4_INT_PARAMS) != (msg.param_type == M.MAV_PARAM_TYPE_INT32):
            return  # PX4: "param types mismatch", nothing set, no PARAM_VALUE
        if self.px4 and name in PX4_INT_PARAMS:
            value = float(struct.unpack("<i", struct.pack("<f", msg.param_value))[0])
        if math.isfinite(value):
            self._store_param(name, value)
            self._send(self._param_msg(name))
