"""The mission protocol's plan ids: the ``uint32`` a vehicle gives each stored mission, fence and rally plan
(mavlink.io mission protocol, "Detecting Plan Changes"). It answers an upload in ``MISSION_ACK.opaque_id``, a
download in ``MISSION_COUNT.opaque_id`` and streams the current one in ``MISSION_CURRENT.mission_id``; 0 means the
vehicle gives no ids (ArduCopter, measured against its SITL) or holds no plan. PX4 sets it to the CRC32 of the plan
and changes it with the plan, also when its navigator replaces the stored mission
(``MavlinkMissionManager::send_mission_current`` / ``update_active_mission``, src/modules/mavlink/mavlink_mission.cpp).

These are MAVLink 2 extension fields of ``common.xml`` that pymavlink's bundled definitions (2.4.50) do not
declare, so they are read from the received frame's payload and written after the declared fields; their byte
offsets follow from the message definitions (extension fields come after the base fields, in declaration order).
"""
from __future__ import annotations

import functools
import struct
from typing import Any

#: message type -> (the plan id's field name, its byte offset in the payload): MISSION_ACK (target_system,
#: target_component, type; extension mission_type) 4; MISSION_COUNT (count, target_system, target_component;
#: mission_type) 5; MISSION_CURRENT (seq; total, mission_state, mission_mode) 6
PLAN_ID_FIELDS = {"MISSION_ACK": ("opaque_id", 4), "MISSION_COUNT": ("opaque_id", 5),
                  "MISSION_CURRENT": ("mission_id", 6)}
_MAVLINK2_MAGIC = 0xFD
_MAVLINK2_HEADER = 10  # magic, len, incompat and compat flags, seq, sysid, compid, 3-byte msgid


def plan_id(msg: Any) -> int:
    """The plan id a received MISSION_ACK, MISSION_COUNT or MISSION_CURRENT carries: the declared field where the
    message definitions have it, else read from the frame's payload (zero-padded: MAVLink 2 drops trailing zero
    bytes). 0 for a MAVLink 1 frame (no extensions), a message not received from a link, or another type. Raises
    AttributeError for an object that is no pymavlink message."""
    field = PLAN_ID_FIELDS.get(msg.get_type())
    if field is None:
        return 0
    declared = getattr(msg, field[0], None)
    if declared is not None:
        return int(declared)
    buf = bytes(msg.get_msgbuf())
    if len(buf) < _MAVLINK2_HEADER or buf[0] != _MAVLINK2_MAGIC:
        return 0
    payload = buf[_MAVLINK2_HEADER:_MAVLINK2_HEADER + buf[1]].ljust(field[1] + 4, b"\0")
    return struct.unpack_from("<I", payload, field[1])[0]


def with_plan_id(msg: Any, value: int) -> Any:
    """``msg`` (a pymavlink MISSION_ACK, MISSION_COUNT or MISSION_CURRENT built by its ``*_encode``) as a message
    that packs ``value`` (uint32) as its plan id after the declared fields. Raises ValueError for another message
    type or a value outside uint32."""
    if msg.get_type() not in PLAN_ID_FIELDS:
        raise ValueError(f"with_plan_id: {msg.get_type()} carries no plan id")
    if not 0 <= int(value) <= 0xFFFFFFFF:
        raise ValueError(f"with_plan_id: value must be a uint32, got {value!r}")
    out = _with_id_class(type(msg))(*(getattr(msg, f) for f in msg.fieldnames))
    out.plan_id_value = int(value)
    return out


@functools.lru_cache(maxsize=None)
def _with_id_class(cls: type) -> type:
    """A subclass of the generated message class ``cls`` whose ``pack`` appends the plan id: the generated
    ``pack`` packs the declared fields and hands the payload to the base class's ``_pack`` (header, CRC with the
    message's CRC extra, which covers only base fields, and signing), as this one does with four bytes more."""
    offset = PLAN_ID_FIELDS[cls.msgname][1]

    def pack(self: Any, mav: Any, force_mavlink1: bool = False) -> bytes:
        declared = self.unpacker.pack(*(getattr(self, f) for f in self.ordered_fieldnames))
        payload = declared.ljust(offset, b"\0")[:offset] + struct.pack("<I", self.plan_id_value)
        return self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1)

    return type(cls.__name__ + "WithPlanId", (cls,), {"pack": pack})
