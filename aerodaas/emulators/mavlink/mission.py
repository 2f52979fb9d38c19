"""The mission protocol, vehicle side (MISSION_COUNT / MISSION_REQUEST(_INT) / MISSION_ITEM(_INT) / MISSION_ACK; mavlink.io/en/services/mission.html)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.constants import (_GLOBAL_FRAMES, _MISSION_COMMANDS, _MISSION_FRAMES, _NAV_COMMANDS,
                                                 _PROTOCOL_RETRIES, _PROTOCOL_TIMEOUT_S)
from aerodaas.emulators.mavlink.link import EmulatorLink
from aerodaas.emulators.mavlink.state import EmulatorState, MissionStore
from aerodaas.emulators.mavlink.telemetry import Telemetry
from aerodaas.missionfile.items import float32
from aerodaas.missionfile.plan_ids import with_plan_id

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link

M = mavlink

__all__ = ["MissionProtocol"]
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
#: mission type -> the commands its items may carry (the items: :meth:`.state.MissionStore.typed_items`)
_TYPED = {M.MAV_MISSION_TYPE_FENCE: _FENCE_COMMANDS, M.MAV_MISSION_TYPE_RALLY: {M.MAV_CMD_NAV_RALLY_POINT}}


class MissionProtocol:
    """The mission protocol, vehicle side, over ``link``: uploads into and downloads from ``store`` (ArduPilot keeps
    home at item 0; ``state`` gives home and the flavour), MISSION_CURRENT through ``telemetry``. ``mission_int``:
    None asks for items as the firmware does (ArduPilot MISSION_REQUEST, PX4 MISSION_REQUEST_INT) and accepts either
    form; True asks with MISSION_REQUEST_INT; False emulates older firmware that asks with MISSION_REQUEST and answers
    MISSION_REQUEST_INT with MISSION_ITEM. A request not answered in 1.5 vehicle seconds is re-sent, 5 times, then the
    upload is CANCELLED (:meth:`transfer_tick`). Not locked: the vehicle calls it under its lock.

    Besides the mission it keeps the fence (``fence_items``, MAV_MISSION_TYPE_FENCE) and the rally points
    (``rally_items``, MAV_MISSION_TYPE_RALLY), each uploaded and downloaded with the same protocol and its own
    ``mission_type`` (mavlink.io mission protocol, "Mission Types"). Like ArduPilot (MissionItemProtocol_Fence
    ``get_item_as_mission_item``) a fence item is stored with only its command, ``param1`` (vertex count or radius)
    and ``x``/``y``, and read back with ``z`` 0; a rally point keeps its altitude."""

    def __init__(self, state: EmulatorState, store: MissionStore, link: EmulatorLink, telemetry: Telemetry,
                 mission_int: bool | None = None) -> None:
        self.state, self.store, self.link, self.telemetry = state, store, link, telemetry
        self.mission_int = mission_int
        self._transfer: _Transfer | None = None
        self._mission_item_warned = False
        self._enc = link.enc

    def transfer_tick(self) -> None:
        """Per physics step: re-send the request of an upload that stalled, or cancel it after the retries (or when
        its link closed)."""
        tr = self._transfer
        if tr is not None and self.state.t > tr.deadline:
            tr.retries += 1
            if tr.retries > _PROTOCOL_RETRIES or tr.link not in self.link.peers:
                self._transfer = None
                self._mission_ack(tr.link, tr.sysid, tr.compid, M.MAV_MISSION_OPERATION_CANCELLED)
            else:
                self._request_next()

    def home_item(self) -> Any:
        """ArduPilot's item 0: home (the EKF origin before there is one) as MISSION_ITEM_INT."""
        st = self.state
        h = st.home or st.origin
        return self._enc.mission_item_int_encode(0, 0, 0, M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0,
                                                 int(round(h.lat * 1e7)), int(round(h.lon * 1e7)), float(h.alt), 0)

    def _mission_ack(self, link: _Link, sysid: int, compid: int, result: int, mission_type: int = 0,
                     plan_id: int = 0) -> None:
        """MISSION_ACK; ``plan_id``: the new mission's id (``opaque_id``), which PX4 answers an upload with."""
        ack = self._enc.mission_ack_encode(sysid, compid, result, mission_type)
        self.link.send(with_plan_id(ack, plan_id) if plan_id else ack, link)

    def on_mission_count(self, link: _Link, msg: Any) -> None:
        """MISSION_COUNT: an upload starts (count 0 clears; over 700 items: NO_SPACE; an unknown mission type:
        UNSUPPORTED)."""
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        mtype = getattr(msg, "mission_type", 0)
        if mtype in _TYPED:
            if msg.count == 0:
                self.store.set_typed_items(mtype, [])
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
            self.store.mission = []
            self._transfer = None
            self._mission_ack(link, *src, M.MAV_MISSION_ACCEPTED)
            return
        if msg.count > 700:
            self._mission_ack(link, *src, M.MAV_MISSION_NO_SPACE)
            return
        self._transfer = _Transfer(link, src[0], src[1], msg.count)
        self._request_next()

    def _request_next(self) -> None:
        st = self.state
        tr = self._transfer
        seq = len(tr.items)
        tr.deadline = st.t + _PROTOCOL_TIMEOUT_S
        # ArduPilot asks with the float MISSION_REQUEST and takes either item form back (libraries/GCS_MAVLink/
        # MissionItemProtocol.cpp, as the trace shows); PX4 asks with MISSION_REQUEST_INT
        as_int = self.mission_int if self.mission_int is not None else st.px4
        request = self._enc.mission_request_int_encode if as_int else self._enc.mission_request_encode
        self.link.send(request(tr.sysid, tr.compid, seq, tr.mission_type), tr.link)

    def _check_item(self, msg: Any) -> int:
        st = self.state
        if msg.command not in _MISSION_COMMANDS:
            return M.MAV_MISSION_UNSUPPORTED
        positional = msg.command in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LAND,
                                     M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LOITER_UNLIM)
        if msg.frame not in _MISSION_FRAMES or (positional and msg.frame == M.MAV_FRAME_MISSION
                                                and msg.command == M.MAV_CMD_NAV_WAYPOINT):
            return M.MAV_MISSION_UNSUPPORTED_FRAME
        if st.px4 and not positional and msg.frame != M.MAV_FRAME_MISSION:
            # PX4 takes a command without a position (RTL, DO_CHANGE_SPEED) only in MAV_FRAME_MISSION
            # (MavlinkMissionManager::parse_mavlink_mission_item: in a global frame, MAV_MISSION_UNSUPPORTED)
            return M.MAV_MISSION_UNSUPPORTED
        return M.MAV_MISSION_ACCEPTED

    def store_item(self, link: _Link, msg: Any, is_int: bool) -> None:
        """A MISSION_ITEM_INT (``is_int``) or MISSION_ITEM of the upload in progress from ``link``: checked and
        stored as the INT form; the next one asked for, or the upload ACCEPTED when it was the last."""
        st = self.state
        tr = self._transfer
        if tr is None or link is not tr.link:
            return
        if getattr(msg, "mission_type", 0) != tr.mission_type:
            return
        if tr.mission_type in _TYPED:
            self.store_typed(link, msg, is_int)
            return
        expected = len(tr.items)
        if msg.seq != expected:
            if msg.seq > expected:  # out of order: ask again for the one we need
                self._request_next()
            return
        if not is_int and not st.px4 and self.mission_int is not False and not self._mission_item_warned:
            self._mission_item_warned = True  # MissionItemProtocol::send_mission_item_warning, once per boot
            self.link.text(M.MAV_SEVERITY_WARNING, "got MISSION_ITEM; GCS should send MISSION_ITEM_INT")
        if not is_int:  # MISSION_ITEM (float): store as the INT form
            x, y = msg.x, msg.y
            if msg.frame in _GLOBAL_FRAMES:
                x, y = x * 1e7, y * 1e7
            msg = self._enc.mission_item_int_encode(0, 0, msg.seq, msg.frame, msg.command, msg.current,
                                                    msg.autocontinue, msg.param1, msg.param2, msg.param3, msg.param4,
                                                    int(round(x)), int(round(y)), msg.z, 0)
        if not (st.px4 is False and msg.seq == 0):  # ArduPilot's item 0 is home, whatever was sent
            res = self._check_item(msg)
            if res != M.MAV_MISSION_ACCEPTED:
                self._transfer = None
                self._mission_ack(link, tr.sysid, tr.compid, res)
                self.link.text(M.MAV_SEVERITY_WARNING, f"Mission item {msg.seq} rejected: command {msg.command}")
                return
            if not st.px4 and msg.command not in _POSITION_COMMANDS:
                # ArduPilot stores no location for it (AP_Mission::stored_in_location) and returns it with frame 0
                # and x/y/z 0 (AP_Mission::mission_cmd_to_mavlink_int)
                msg = self._enc.mission_item_int_encode(0, 0, msg.seq, 0, msg.command, msg.current, msg.autocontinue,
                                                        msg.param1, msg.param2, msg.param3, msg.param4, 0, 0, 0.0, 0)
            elif not st.px4:
                msg = self._as_ardupilot_stores(msg)
        tr.items.append(msg)
        if len(tr.items) == tr.count:
            self.store.mission = tr.items
            if not st.px4:
                self.store.mission[0] = self.home_item()
            self.store.seq = 0 if st.px4 else min(1, len(self.store.mission) - 1)
            self.store.run_state = "idle"
            self._transfer = None
            self._mission_ack(link, tr.sysid, tr.compid, M.MAV_MISSION_ACCEPTED, plan_id=self.store.mission_id())
            self.link.text(M.MAV_SEVERITY_INFO, f"Flight plan received ({tr.count} items)")
            # PX4 announces the new mission at once on the uploading link only (its other links at their 1 Hz:
            # MavlinkMissionManager::send, the sequence it last sent being shared by all its links)
            self.telemetry.emit(M.MAVLINK_MSG_ID_MISSION_CURRENT, link if st.px4 else None)
        else:
            self._request_next()

    def store_typed(self, link: _Link, msg: Any, is_int: bool) -> None:
        """A fence or rally item of the transfer in progress (see the class docstring)."""
        tr = self._transfer
        commands = _TYPED[tr.mission_type]
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
            self.store.set_typed_items(tr.mission_type, tr.items)
            self._transfer = None
            self._mission_ack(link, tr.sysid, tr.compid, M.MAV_MISSION_ACCEPTED, tr.mission_type)
        else:
            self._request_next()

    def on_mission_item_int(self, link: _Link, msg: Any) -> None:
        """MISSION_ITEM_INT: :meth:`store_item`."""
        self.store_item(link, msg, True)

    def on_mission_item(self, link: _Link, msg: Any) -> None:
        """MISSION_ITEM (float latitude/longitude): :meth:`store_item`."""
        self.store_item(link, msg, False)

    def _download_items(self) -> list[Any]:
        st = self.state
        if not st.px4:
            return [self.home_item()] + list(self.store.mission[1:]) if self.store.mission else [self.home_item()]
        return list(self.store.mission)

    def on_mission_request_list(self, link: _Link, msg: Any) -> None:
        """MISSION_REQUEST_LIST: a download starts with MISSION_COUNT of the type asked (0 for an unknown one)."""
        mtype = getattr(msg, "mission_type", 0)
        if mtype in _TYPED:
            self.link.send(self._enc.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(),
                                                      len(self.store.typed_items(mtype)), mtype), link)
            return
        if mtype != M.MAV_MISSION_TYPE_MISSION:
            self.link.send(self._enc.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(), 0,
                                                      msg.mission_type), link)
            return
        count = self._enc.mission_count_encode(msg.get_srcSystem(), msg.get_srcComponent(),
                                               len(self._download_items()), 0)
        plan_id = self.store.mission_id()  # PX4 answers a download with the stored mission's id
        self.link.send(with_plan_id(count, plan_id) if plan_id else count, link)

    def _as_ardupilot_stores(self, msg: Any) -> Any:
        """A MISSION_ITEM_INT with a position as ArduPilot stores it (``AP_Mission::mavlink_int_to_mission_cmd``):
        the altitude in whole centimetres (an int32 of ``packet.z * 100.0f``, truncated, read back as
        ``alt * 0.01f``); a NAV_WAYPOINT's hold time and a NAV_LOITER_TIME's time in whole seconds (``cmd.p1 =
        packet.param1``, a uint16)."""
        alt_cm = int(float32(float32(msg.z) * 100.0))  # C's float to int32: truncated toward zero
        p1 = msg.param1
        if msg.command in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME) and 0.0 <= p1 < 65536.0:
            p1 = float(int(p1))
        return self._enc.mission_item_int_encode(0, 0, msg.seq, msg.frame, msg.command, msg.current, msg.autocontinue,
                                                 p1, msg.param2, msg.param3, msg.param4, msg.x, msg.y,
                                                 float32(float32(alt_cm) * float32(0.01)), 0)

    def _send_item(self, link: _Link, msg: Any, as_int: bool) -> None:
        mtype = getattr(msg, "mission_type", 0)
        items = list(self.store.typed_items(mtype)) if mtype in _TYPED else self._download_items()
        if not 0 <= msg.seq < len(items):
            self._mission_ack(link, msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_INVALID_SEQUENCE,
                              mtype)
            return
        it = items[msg.seq]
        cur = 1 if msg.seq == self.store.seq and mtype == 0 else 0
        if as_int:
            out = self._enc.mission_item_int_encode(msg.get_srcSystem(), msg.get_srcComponent(), msg.seq, it.frame,
                                                    it.command, cur, it.autocontinue, it.param1, it.param2, it.param3,
                                                    it.param4, it.x, it.y, it.z, mtype)
        else:
            # float degrees as each firmware computes them: ArduPilot in float32 (``mission_cmd_to_mavlink``:
            # ``cmd.content.location.lat * 1.0e-7f``, the int32 made a float first), PX4 in double
            # (``MavlinkMissionManager::format_mavlink_mission_item``: ``mission_item->lat``, a double)
            if it.frame not in _GLOBAL_FRAMES:
                x, y = float(it.x), float(it.y)
            elif self.state.px4:
                x, y = it.x * 1e-7, it.y * 1e-7
            else:
                x, y = float32(float32(it.x) * float32(1.0e-7)), float32(float32(it.y) * float32(1.0e-7))
            out = self._enc.mission_item_encode(msg.get_srcSystem(), msg.get_srcComponent(), msg.seq, it.frame,
                                                it.command, cur, it.autocontinue, it.param1, it.param2, it.param3,
                                                it.param4, x, y, it.z, mtype)
        self.link.send(out, link)

    def on_mission_request_int(self, link: _Link, msg: Any) -> None:
        """MISSION_REQUEST_INT: the item as MISSION_ITEM_INT (older firmware, ``mission_int=False``: MISSION_ITEM)."""
        mtype = getattr(msg, "mission_type", 0)
        if mtype == M.MAV_MISSION_TYPE_MISSION or mtype in _TYPED:
            self._send_item(link, msg, self.mission_int is not False)  # older firmware answers with MISSION_ITEM

    def on_mission_request(self, link: _Link, msg: Any) -> None:
        """MISSION_REQUEST: the item as MISSION_ITEM."""
        mtype = getattr(msg, "mission_type", 0)
        if mtype == M.MAV_MISSION_TYPE_MISSION or mtype in _TYPED:
            self._send_item(link, msg, False)

    def on_mission_clear_all(self, link: _Link, msg: Any) -> None:
        """MISSION_CLEAR_ALL of a mission type (ALL clears the mission, fence and rally points): ACCEPTED."""
        mtype = getattr(msg, "mission_type", 0)
        if mtype in _TYPED or mtype == M.MAV_MISSION_TYPE_ALL:
            for typed in ([mtype] if mtype in _TYPED else list(_TYPED)):
                self.store.set_typed_items(typed, [])
            if mtype in _TYPED:
                self._mission_ack(link, msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_ACCEPTED, mtype)
                return
        self.store.mission = []
        self.store.seq = 0
        self.store.run_state = "idle"
        self._mission_ack(link, msg.get_srcSystem(), msg.get_srcComponent(), M.MAV_MISSION_ACCEPTED,
                          getattr(msg, "mission_type", 0))

    def on_mission_set_current(self, link: _Link, msg: Any) -> None:
        """MISSION_SET_CURRENT: that item is current (one out of range is ignored)."""
        if 0 <= msg.seq < len(self.store.mission):
            self.set_current(msg.seq)

    def set_current(self, seq: int) -> None:
        """Item ``seq`` is current, not started; announced with MISSION_CURRENT."""
        self.store.seq = seq
        self.store.item_started = False
        self.store.item_reached_at = None
        self.telemetry.emit(M.MAVLINK_MSG_ID_MISSION_CURRENT)
