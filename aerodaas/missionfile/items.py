"""One mission item: :class:`MissionItem` (a MAVLink ``MISSION_ITEM_INT`` row, or a verbatim QGroundControl
ComplexItem) and its validation, including the QGroundControl ``SimpleItem`` JSON object (``MissionItem::load``)
that ``.plan`` files and survey / corridor-scan ComplexItems hold."""
from __future__ import annotations

import math
import struct
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from aerodaas.missionfile._common import _fail, _is_number
from aerodaas.missionfile.commands import (COMPLEX_ITEM_COMMAND, MISSION_FRAMES, NAV_KINDS, _FRAME_NAMES,
                                           _GLOBAL_FRAMES, command_name, frame_name)


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


def float32(v: float) -> float:
    """``v`` as a MAVLink ``float`` field carries it (IEEE 754 single precision, rounded to nearest), back as a
    Python float. Raises OverflowError beyond float32's range."""
    return struct.unpack("<f", struct.pack("<f", v))[0]


class MissionItem(_Model):
    """One MAVLink mission item (``MISSION_ITEM_INT``), or one verbatim QGroundControl ComplexItem.

    * ``seq``: mission sequence number with the home position at 0 (ArduPilot / Mission Planner row number,
      QGroundControl ``doJumpId``); ``MAV_CMD_DO_JUMP`` targets refer to it.
    * ``command``: ``MAV_CMD`` number (e.g. ``MAV_CMD_NAV_WAYPOINT`` = 16).
    * ``frame``: ``MAV_FRAME`` of ``x``/``y``/``z`` (0 AMSL, 2 mission/no position, 3 relative to home, 5/6 the
      ``_INT`` aliases of 0/3, 10/11 above terrain).
    * ``params``: exactly 7 values ``[param1, param2, param3, param4, x, y, z]``: for positional commands ``x``
      is latitude (degrees), ``y`` longitude (degrees), ``z`` altitude (metres, per ``frame``). ``None`` stands
      for NaN ("unset", JSON ``null``).
    * ``autocontinue``: continue to the next item when this one completes.
    * ``raw``: the verbatim ``.plan`` JSON object of a ComplexItem; then ``command`` is
      :data:`COMPLEX_ITEM_COMMAND` (0), ``frame`` is 2 and every param is ``None``.
    """

    seq: int = Field(ge=0)
    command: int = Field(ge=0, le=65535)
    frame: int = Field(ge=0, le=255)
    params: list[float | None] = Field(default_factory=lambda: [None] * 7)
    autocontinue: bool = True
    raw: dict[str, Any] | None = None

    @field_validator("params", mode="before")
    @classmethod
    def _seven_params(cls, v: Any) -> list[float | None]:
        if not isinstance(v, (list, tuple)) or len(v) != 7:
            raise ValueError(f"params must hold exactly 7 values [param1..param4, x, y, z], got {v!r}")
        out: list[float | None] = []
        for i, p in enumerate(v):
            if p is None:
                out.append(None)
                continue
            if isinstance(p, bool) or not isinstance(p, (int, float)):
                raise ValueError(f"params[{i}] must be a number or null, got {p!r}")
            f = float(p)
            if math.isnan(f):
                out.append(None)
            elif math.isinf(f):
                raise ValueError(f"params[{i}] must be finite, got {p!r}")
            else:
                out.append(f)
        return out

    @model_validator(mode="after")
    def _consistent(self) -> "MissionItem":
        if self.raw is not None:
            if self.command != COMPLEX_ITEM_COMMAND or any(p is not None for p in self.params):
                raise ValueError("a ComplexItem (raw set) must have command 0 and all params None")
            if not isinstance(self.raw.get("complexItemType"), str):
                raise ValueError(f"raw: a ComplexItem needs a string 'complexItemType', got {self.raw!r:.200}")
        elif self.command == COMPLEX_ITEM_COMMAND:
            raise ValueError("command 0 is not a MAVLink command (only ComplexItems, with raw, use 0)")
        return self

    @property
    def is_complex(self) -> bool:
        """True for a verbatim ``.plan`` ComplexItem."""
        return self.raw is not None

    @property
    def complex_type(self) -> str | None:
        """``complexItemType`` of a ComplexItem (``"survey"``, ``"CorridorScan"``, ``"StructureScan"``...)."""
        return self.raw.get("complexItemType") if self.raw is not None else None

    @property
    def nav_kind(self) -> str:
        """What the item makes the vehicle do, in the drone's words: ``"waypoint"`` (NAV_WAYPOINT), ``"takeoff"``,
        ``"land"``, ``"rtl"`` (NAV_RETURN_TO_LAUNCH), or ``"other"``."""
        return NAV_KINDS.get(self.command, "other")

    def describe(self) -> str:
        """``"item 3 (MAV_CMD_NAV_LAND (21))"`` / ``"item 2 (ComplexItem 'StructureScan')"`` for messages."""
        if self.raw is not None:
            return f"item {self.seq} (ComplexItem {self.complex_type!r})"
        return f"item {self.seq} ({command_name(self.command)})"


def _check_position(src: str, where: str, frame: int, params: list[float | None]) -> None:
    """Latitude/longitude range check for items in a global frame (x, y are degrees there)."""
    if frame not in _GLOBAL_FRAMES:
        return
    lat, lon = params[4], params[5]
    if lat is not None and not -90.0 <= lat <= 90.0:
        raise _fail(src, where, f"latitude (x) {lat!r} is outside [-90, 90] degrees")
    if lon is not None and not -180.0 <= lon <= 180.0:
        raise _fail(src, where, f"longitude (y) {lon!r} is outside [-180, 180] degrees")


def _check_command_frame(src: str, where: str, command: Any, frame: Any) -> None:
    if not isinstance(command, int) or isinstance(command, bool) or not 0 < command <= 65535:
        raise _fail(src, where, f"command must be a MAV_CMD number 1..65535, got {command!r}")
    if not isinstance(frame, int) or isinstance(frame, bool):
        raise _fail(src, where, f"frame must be an integer MAV_FRAME, got {frame!r}")
    if frame not in MISSION_FRAMES:
        what = frame_name(frame) if frame in _FRAME_NAMES else f"unknown frame {frame}"
        raise _fail(src, where, f"{what} is not a mission frame (expected one of "
                                f"{', '.join(frame_name(f) for f in sorted(MISSION_FRAMES))})")


def _parse_simple_item(src: str, where: str, obj: Any, default_seq: int) -> MissionItem:
    """A QGroundControl ``SimpleItem`` (``MissionItem::load``: type/command/frame/params/autoContinue required,
    doJumpId optional; the v2 ``coordinate`` key is folded into params like QGroundControl does)."""
    if not isinstance(obj, dict):
        raise _fail(src, where, f"mission item must be a JSON object, got {obj!r:.80}")
    if obj.get("type") != "SimpleItem":
        raise _fail(src, where, f"type must be 'SimpleItem', got {obj.get('type')!r}")
    for key in ("command", "frame", "params", "autoContinue"):
        if key not in obj:
            raise _fail(src, where, f"missing required key {key!r}")
    seq = obj.get("doJumpId", default_seq)
    if not isinstance(seq, int) or isinstance(seq, bool) or seq < 0:
        raise _fail(src, where, f"doJumpId must be a non-negative integer, got {seq!r}")
    command, frame = obj["command"], obj["frame"]
    _check_command_frame(src, f"{where} (doJumpId {seq})", command, frame)
    where = f"{where} (doJumpId {seq}, {command_name(command)})"
    params = obj["params"]
    if "coordinate" in obj and isinstance(params, list) and len(params) == 4:
        coord = obj["coordinate"]
        if not isinstance(coord, list) or len(coord) != 3:
            raise _fail(src, where, f"coordinate must be [latitude, longitude, altitude], got {coord!r}")
        params = list(params) + list(coord)
    if not isinstance(params, list) or len(params) != 7:
        raise _fail(src, where, f"params must be a list of 7 values, got {params!r}")
    for i, p in enumerate(params):
        if p is not None and not _is_number(p):
            raise _fail(src, where, f"params[{i}] must be a number or null, got {p!r}")
        if _is_number(p) and math.isinf(p):
            raise _fail(src, where, f"params[{i}] must be finite, got {p!r}")
    if not isinstance(obj["autoContinue"], bool):
        raise _fail(src, where, f"autoContinue must be true or false, got {obj['autoContinue']!r}")
    item = MissionItem(seq=seq, command=command, frame=frame, params=params, autocontinue=obj["autoContinue"])
    _check_position(src, where, frame, item.params)
    return item
