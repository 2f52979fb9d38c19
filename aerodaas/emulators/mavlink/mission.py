"""The mission protocol, vehicle side (MISSION_COUNT / MISSION_REQUEST(_INT) / MISSION_ITEM(_INT) / MISSION_ACK; mavlink.io/en/services/mission.html)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.constants import _GLOBAL_FRAMES, _MISSION_COMMANDS, _MISSION_FRAMES, _NAV_COMMANDS, _PROTOCOL_TIMEOUT_S


from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link

M = mavlink
#: the mission commands with a position (the others: NAV_RETURN_TO_LAUNCH, DO_CHANGE_SPEED)
_POSITION_COMMANDS = _NAV_COMMANDS - {M.MAV_CMD_NAV_RETURN_TO_LAUNCH}


@dataclass
class _Transfer:
    """A mission upload in progress (vehicle side)."""

    link: _Link
    sysid: int
    compid: int
    count: int
    items: list = field(default_factory=list)
    deadline: float = 0.0
    retries: int = 0
    mission_type: int = 0


#: the fence items a vehicle accepts (common.xml MAV_CMD_NAV_FENCE_*; ArduPilot MissionItemProtocol_Fence.cpp
#: convert_MISSION_ITEM_INT_to_AC_PolyFenceItem) and the rally point item (MAV_CMD_NAV_RALLY_POINT)
_FENCE_COMMANDS = {M.MAV_CMD_NAV_FENCE_RETURN_POINT, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                   M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
                   M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION}
_TYPED = {M.MAV_MISSION_TYPE_FENCE: ("fence_items", _FENCE_COMMANDS),
          M.MAV_MISSION_TYPE_RALLY: ("rally_items", {M.MAV_CMD_NAV_RALLY_POINT})}


class MissionMixin:
    """Part of :class:`~aerodaas.emulators.mavlink.MavlinkVehicleEmulator` (state lives there).

    Besides the mission it keeps the fence (``fence_items``, MAV_MISSION_TYPE_FENCE) and the rally points
    (``rally_items``, MAV_MISSION_TYPE_RALLY), each uploaded and downloaded with the same protocol and its own
    ``mission_type`` (mavlink.io mission protocol, "Mission Types"). Like ArduPilot (MissionItemProtocol_Fence
    ``get_item_as_mission_item``) a fence item is stored with only its command, ``param1`` (vertex count or radius)
    and ``x``/``y``, and read back with ``z`` 0; a rally point keeps its altitude."""

    def _mission_nav_items(self) -> list[int]:
        first = 0 if self.px4 else 1
        return [i for i in range(first, len(self.mission)) if self.mission[i].command in _NAV_COMMANDS]

    def _starts_with_takeoff(self) -> bool:
        nav = self._mission_nav_items()
        return bool(nav) and self.mission[nav[0]].command == M.MAV_CMD_NAV_TAKEOFF

    def _home_item(self) -> Any:
        h = self.home or self.origin
        return self._enc.mission_item_int_encode(0, 0, 0, M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0,
                                                 int(round(h.lat * 1e7)), int(round(h.lon * 1e7)), float(h.alt), 0)

    def _mission_ack(self, link: _Link, sysid: int, compid: int, result: int, mission_type: int = 0) -> None:
        self._send(self._enc.mission_ack_encode(sysid, compid, result, mission_type), link)

    def _on_mission_count(self, link: _Link, msg: Any) -> None:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        mtype = getattr(msg, "mission_type", 0)
        if mtype in _TYPED:
            if msg.count == 0:
                setattr(self, _TYPED[mtype][0], [])
                self._transfer = None
                self._mission_ack(link, *src, M.MAV_MISSION_ACCEPTED, mtype)
            elif msg.count > 700:
                self._mission_ack(link, *src, M.MAV_MISSION_NO_SPACE, mtype)
            else:
                self._transfer = _Transfer(link, src[0], src[1], msg.count, mission_type=mtype)
                self._request_next()
            return
        if mtype != M.MAV_MISSION_TYPE_MISSION:
            self._mission_ack(link, *src, M.MAV_MISSION_UNSUPPORTED, msg.mission_type)
            return
        if msg.count == 0:
            self.mission = []
            self._transfer = None
            self._mission_ack(link, *src, M.MAV_MISSION_ACCEPTED)
            return
        if msg.count > 700:
            self._mission_ack(link, *src, M.MAV_MISSION_NO_SPACE)
            return
        self._transfer = _Transfer(link, src[0], src[1], msg.count)
        self._request_next()

    def _request_next(self) -> None:
        tr = self._transfer
        seq = len(tr.items)
        tr.deadline = self.t + _PROTOCOL_TIMEOUT_S
        # ArduPilot asks with the float MISSION_REQUEST and takes either item form back (libraries/GCS_MAVLink/
        # MissionItemProtocol.cpp, as the trace shows); PX4 asks with MISSION_REQUEST_INT
        as_int = self.mission_int if self.mission_int is not None else self.px4
        request = self._enc.mission_request_int_encode if as_int else self._enc.mission_request_encode
        self._send(request(tr.sysid, tr.compid, seq, tr.mission_type), tr.link)

    def _check_item(self, msg: Any) -> int:
        if msg.command not in _MISSION_COMMANDS:
            return M.MAV_MISSION_UNSUPPORTED
        positional = msg.command in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LAND,
                                     M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LOITER_UNLIM)
        if msg.frame not in _MISSION_FRAMES or (positional and msg.frame == M.MAV_FRAME_MISSION
                                                and msg.command == M.MAV_CMD_NAV_WAYPOINT):
            return M.MAV_MISSION_UNSUPPORTED_FRAME
        if self.px4 and not positional and msg.frame != M.MAV_FRAME_MISSION:
            # PX4 takes a command without a position (RTL, DO_CHANGE_SPEED) only in MAV_FRAME_MISSION
            # (MavlinkMissionManager::parse_mavlink_mission_item: in a global frame, MAV_MISSION_UNSUPPORTED)
            return M.MAV_MISSION_UNSUPPORTED
        return M.MAV_MISSION_ACCEPTED

    def _store_item(self, link: _Link, msg: Any, is_int: bool) -> None:
        tr = self._transfer
        if tr is None or link is not tr.link:
            return
        if getattr(msg, "mission_type", 0) != tr.mission_type:
            return
        if tr.mission_type in _TYPED:
            self._store_typed(link, msg, is_int)
            return
        expected = len(tr.items)
        if msg.seq != expected:
            if msg.seq > expected:  # out of order: ask again for the one we need
                self._request_next()
            return
        if not is_int and not self.px4 and self.mission_int is not False and not self._mission_item_warned:
            self._mission_item_warned = True  # MissionItemProtocol::send_mission_item_warning, once per boot
            self._text(M.MAV_SEVERITY_WARNING, "got MISSION_ITEM; GCS should send MISSION_ITEM_INT")
        if not is_int:  # MISSION_ITEM (float): store as the INT form
            x, y = msg.x, msg.y
            if msg.frame in _GLOBAL_FRAMES:
                x, y = x * 1e7, y * 1e7
            msg = self._enc.mission_item_int_encode(0, 0, msg.seq, msg.frame, msg.command, msg.current,
                                                    msg.autocontinue, msg.param1, msg.param2, msg.param3, msg.param4,
                                                    int(round(x)), int(round(y)), msg.z, 0)
        if not (self.px4 is False and msg.seq == 0):  # ArduPilot's item 0 is home, whatever was sent
            res = self._check_item(msg)
            if res != M.MAV_MISSION_ACCEPTED:
                self._transfer = None
                self._mission_ack(link, tr.sysid, tr.compid, res)
                self._text(M.MAV_SEVERITY_WARNING, f"Mission item {msg.seq} rejected: command {msg.command}")
                return
            if not self.px4 and msg.command not in _POSITION_COMMANDS:
                # ArduPilot stores no location for it (AP_Mission::stored_in_location) and returns it with frame 0
                # and x/y/z 0 (AP_Mission::mission_cmd_to_mavlink_int)
                msg = self._enc.mission_item_int_encode(0, 0, msg.seq, 0, msg.command, msg.current, msg.autocontinue,
                                                        msg.param1, msg.param2, msg.param3, msg.param4, 0, 0, 0.0, 0)
        tr.items.append(msg)
        if len(tr.items) == tr.count:
            self.mission = tr.items
            if not self.px4:
                self.mission[0] = self._home_item()
            self.mission_seq = 0 if self.px4 else min(1, len(self.mission) - 1)
            self.mission_state = "idle"
            self._transfer = None
            self._mission_ack(link, tr.sysid, tr.compid, M.MAV_MISSION_ACCEPTED)
            self._text(M.MAV_SEVERITY_INFO, f"Flight plan received ({tr.count} items)")
            self._emit(M.MAVLINK_MSG_ID_MISSION_CURRENT)
        else:
            self._request_next()

    def _store_typed(self, link: _Link, msg: Any, is_int: bool) -> None:
        """A fence or rally item of the transfer in progress (see the class docstring)."""
        tr = self._transfer
        attr, commands = _TYPED[tr.mission_type]
        if msg.seq != len(tr.items):
            if msg.seq > len(tr.items):
                self._request_next()
            return
        if msg.command not in commands or msg.frame not in _GLOBAL_FRAMES:
            self._transfer = None
            res = M.MAV_MISSION_UNSUPPORTED if msg.command not in commands else M.MAV_MISSION_UNSUPPORTED_FRAME
            self._mission_ack(link, tr.sysid, tr.compid, res, tr.mission_type)
            return
        k = 1.0 if is_int else 1e7
        fence = tr.mission_type == M.MAV_MISSION_TYPE_FENCE
        tr.items.append(self._enc.mission_item_int_encode(
            0, 0, msg.seq, M.MAV_FRAME_GLOBAL if fence else msg.frame, msg.command, 0, 1, msg.param1,
            0.0 if fence else msg.param2, 0.0 if fence else msg.param3, 0.0 if fence else msg.param4,
            int(round(msg.x * k)), int(round(msg.y * k)), 0.0 if fence else msg.z, tr.mission_type))
        if len(tr.items) == tr.count:
            setattr(self, attr, tr.items)
            self._transfer = None
            self._mission_ack(link, tr.sysid, tr.compid, M.MAV_MISSION_ACCEPTED, tr.mission_type)
        else:
            self._request_next()

    def _on_mission_item_int(self, link: _Link, msg: Any) -> None:
        self._store_item(link, msg, True)

    def _on_mission_item(self, link: _Link, msg: Any) -> None:
        self._store_item(link, msg, False)

    def _download_items(self) -> list[Any]:
        if not self.px4:
            return [self._home_item()] + list(self.mission[1:]) if self.mission else [self._home_item()]
        return list(self.mission)

    def _on_mission_request_list(self, link: _Link, msg: Any) -> None:
        mtype = getattr(msg, "mission_type", 0)
        if mtype in _TYPED:
            self._send(self._enc.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(),
                                                      len(getattr(self, _TYPED[mtype][0])), mtype), link)
            return
        if mtype != M.MAV_MISSION_TYPE_MISSION:
            self._send(self._enc.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(), 0,
                                                      msg.mission_type), link)
            return
        self._send(self._enc.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(),
                                                  len(self._download_items()), 0), link)

    def _send_item(self, link: _Link, msg: Any, as_int: bool) -> None:
        mtype = getattr(msg, "mission_type", 0)
        items = list(getattr(self, _TYPED[mtype][0])) if mtype in _TYPED else self._download_items()
        if not 0 <= msg.seq < len(items):
            self._mission_ack(link, msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_INVALID_SEQUENCE,
                              mtype)
            return
        it = items[msg.seq]
        cur = 1 if msg.seq == self.mission_seq and mtype == 0 else 0
        if as_int:
            out = self._enc.mission_item_int_encode(msg.get_srcSystem(), msg.get_srcComponent(), msg.seq, it.frame,
                                                    it.command, cur, it.autocontinue, it.param1, it.param2, it.param3,
                                                    it.param4, it.x, it.y, it.z, mtype)
        else:
            k = 1e-7 if it.frame in _GLOBAL_FRAMES else 1.0
            out = self._enc.mission_item_encode(msg.get_srcSystem(), msg.get_srcComponent(), msg.seq, it.frame,
                                                it.command, cur, it.autocontinue, it.param1, it.param2, it.param3,
                                                it.param4, it.x * k, it.y * k, it.z, mtype)
        self._send(out, link)

    def _on_mission_request_int(self, link: _Link, msg: Any) -> None:
        mtype = getattr(msg, "mission_type", 0)
        if mtype == M.MAV_MISSION_TYPE_MISSION or mtype in _TYPED:
            self._send_item(link, msg, self.mission_int is not False)  # older firmware answers with MISSION_ITEM

    def _on_mission_request(self, link: _Link, msg: Any) -> None:
        mtype = getattr(msg, "mission_type", 0)
        if mtype == M.MAV_MISSION_TYPE_MISSION or mtype in _TYPED:
            self._send_item(link, msg, False)

    def _on_mission_clear_all(self, link: _Link, msg: Any) -> None:
        mtype = getattr(msg, "mission_type", 0)
        if mtype in _TYPED or mtype == M.MAV_MISSION_TYPE_ALL:
            for attr, _ in ([_TYPED[mtype]] if mtype in _TYPED else _TYPED.values()):
                setattr(self, attr, [])
            if mtype in _TYPED:
                self._mission_ack(link, msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_ACCEPTED, mtype)
                return
        self.mission = []
        self.mission_seq = 0
        self.mission_state = "idle"
        self._mission_ack(link, msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_ACCEPTED,
                          getattr(msg, "mission_type", 0))

    def _on_mission_set_current(self, link: _Link, msg: Any) -> None:
        if 0 <= msg.seq < len(self.mission):
            self._set_current(msg.seq)

    def _set_current(self, seq: int) -> None:
        self.mission_seq = seq
        self.item_started = False
        self.item_reached_at = None
        self._emit(M.MAVLINK_MSG_ID_MISSION_CURRENT)
