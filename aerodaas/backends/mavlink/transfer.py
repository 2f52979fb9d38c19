"""The mission protocol's transfers (mavlink.io mission microservice: MISSION_COUNT / MISSION_REQUEST(_INT) /
MISSION_ITEM_INT / MISSION_ACK, MISSION_REQUEST_LIST, MISSION_CLEAR_ALL), for every MAV_MISSION_TYPE: the
mission (:mod:`.mission`), the fence and rally points (:mod:`.fence`). A concern object of
:class:`~aerodaas.backends.mavlink.MavlinkBackend`."""
from __future__ import annotations

import contextlib
import queue
import threading
import time
from typing import Any, Callable

from aerodaas.backends.base import BackendError, CommandRefused, LinkLost
from aerodaas.backends.mavlink._common import M, _enum_name, _f32
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink.statustext import StatusTexts
from aerodaas.missionfile.plan_ids import plan_id

__all__ = ["MissionTransfer", "FENCE", "RALLY", "Wire"]

FENCE = M.MAV_MISSION_TYPE_FENCE  # 1
RALLY = M.MAV_MISSION_TYPE_RALLY  # 2
_TYPE_NAME = {FENCE: "fence", RALLY: "rally points", M.MAV_MISSION_TYPE_MISSION: "mission"}
#: one fence or rally item as MISSION_ITEM_INT fields: (frame, command, param1..4, x, y, z); x/y degrees x 1e7
Wire = tuple


class MissionTransfer:
    """The mission protocol's exchanges with one vehicle, one at a time (the control thread waits for each).

    It is given its collaborators: ``link`` (sending, the link check, the vehicle's system and component id, the
    MAVLink version ``"1.0"`` / ``"2.0"``; it registers with it, :meth:`MavlinkLink.serve_mission_protocol`, and
    :meth:`offer` is fed every mission message for us on the I/O thread), ``texts`` (the autopilot's latest
    STATUSTEXT since a wall time, for refusals) and ``event`` (records a backend event). ``settings``:
    ``command_timeout_s``, ``command_retries``, ``source_system``.

    State: the queue of mission messages of the exchange under way and whether one is (only then are they
    queued)."""

    def __init__(self, robot_id: str, settings: Any, *, link: MavlinkLink, texts: StatusTexts,
                 event: Callable[..., None]) -> None:
        self.robot_id, self._settings, self._link, self._texts, self._event = robot_id, settings, link, texts, event
        self._queue: queue.Queue = queue.Queue()
        self._active = False
        self._gate = threading.Lock()  # _active and the queue change together (offer on the I/O thread)
        link.serve_mission_protocol(self)

    def offer(self, msg: Any) -> None:
        """A mission message from the vehicle (MISSION_REQUEST(_INT), MISSION_ACK, MISSION_COUNT,
        MISSION_ITEM(_INT)): kept for the exchange under way when it is addressed to us; dropped otherwise."""
        if getattr(msg, "target_system", 0) in (0, self._settings.source_system):
            with self._gate:
                if self._active:
                    self._queue.put(msg)

    def upload_mission(self, wire: list[tuple]) -> int:
        """The upload transfer of the mission's ``wire`` items (frame, command, autocontinue, param1-4, x, y, z)
        (MISSION_COUNT, each item as the autopilot requests it, until its MISSION_ACK). Returns the accepting
        MISSION_ACK's plan id (:func:`~aerodaas.missionfile.plan_ids.plan_id`; 0: the vehicle gives none). Raises
        CommandRefused for a refusing MISSION_ACK."""
        n = len(wire)

        def send_item(seq: int, as_int: bool) -> None:
            # always MISSION_ITEM_INT, also to a MISSION_REQUEST (ArduPilot: "GCS should send MISSION_ITEM_INT";
            # the float MISSION_ITEM loses ~0.4 m of latitude/longitude in float32)
            frame, cmd, auto, p1, p2, p3, p4, xi, yi, z = wire[seq]
            self._link.send(lambda mav: mav.mission_item_int_send(*self._link.target, seq, frame, cmd, 0, auto,
                                                             p1, p2, p3, p4, xi, yi, z, 0))

        def resend(last: Any) -> None:
            if last is None:
                self._link.send(lambda mav: mav.mission_count_send(*self._link.target, n, 0))
            else:
                send_item(*last)

        def on_msg(msg: Any, state: dict) -> bool:
            t = msg.get_type()
            if t in ("MISSION_REQUEST_INT", "MISSION_REQUEST") and getattr(msg, "mission_type", 0) == 0:
                if 0 <= msg.seq < n:
                    state["last"] = (msg.seq, t == "MISSION_REQUEST_INT")
                    state["max"] = max(state["max"], msg.seq)
                    send_item(*state["last"])
                return False
            if t == "MISSION_ACK" and getattr(msg, "mission_type", 0) == 0:
                if msg.type == M.MAV_MISSION_INVALID_SEQUENCE and state["max"] < n - 1:
                    # ArduPilot answers an item that is not the one it asks for now (our answer to a request it
                    # had already repeated) with this ACK and goes on with the transfer (MissionItemProtocol::
                    # handle_mission_item); the next MISSION_REQUEST follows
                    self._event("mission_item_out_of_sequence", last_requested=state["max"])
                    return False
                if msg.type != M.MAV_MISSION_ACCEPTED:
                    raise CommandRefused(self.robot_id, "mission upload", _enum_name("MAV_MISSION_RESULT", msg.type),
                                         self._texts.since(state["start"]))
                state["plan_id"] = plan_id(msg)
                return state["max"] == n - 1 or n == 0
            return False

        return self._transaction("mission upload", lambda: resend(None), resend, on_msg).get("plan_id", 0)

    def _transaction(self, name: str, begin: Callable[[], None], resend: Callable[[Any], None],
                     on_msg: Callable[[Any, dict], bool]) -> dict:
        """Run one mission-protocol exchange: ``begin()``, then feed every mission message to ``on_msg`` until it
        returns True; after ``command_timeout_s`` without progress ``resend(state["last"])`` up to
        ``command_retries`` times (only a message that advances the exchange, i.e. changes ``state``, resets the
        count, so a vehicle answering with something we do not use cannot keep it going for ever)."""
        with self._gate:
            while True:
                try:
                    self._queue.get_nowait()
                except queue.Empty:
                    break
            self._active = True
        state: dict[str, Any] = {"last": None, "max": -1, "start": time.monotonic()}
        try:
            begin()
            retries = 0
            deadline = time.monotonic() + self._settings.command_timeout_s
            while True:
                remaining = deadline - time.monotonic()
                msg = None
                if remaining > 0:
                    try:
                        msg = self._queue.get(timeout=remaining)
                    except queue.Empty:
                        pass
                if msg is None:
                    self._link.check_link(name)
                    retries += 1
                    if retries > self._settings.command_retries:
                        raise BackendError(f"robot {self.robot_id!r}: {name}: no usable answer after {retries} "
                                           f"tries of {self._settings.command_timeout_s:g} s")
                    resend(state["last"])
                    deadline = time.monotonic() + self._settings.command_timeout_s
                    continue
                before = (state["last"], state["max"], state.get("count"))
                if on_msg(msg, state):
                    return state
                if (state["last"], state["max"], state.get("count")) != before:
                    retries = 0
                    deadline = time.monotonic() + self._settings.command_timeout_s
        finally:
            with self._gate:
                self._active = False

    def download_messages(self, mission_type: int, what: str) -> dict[int, Any]:
        """The mission protocol's download of the items of ``mission_type`` (0 mission, 1 fence, 2 rally; MAVLink
        common.xml MAV_MISSION_TYPE): MISSION_REQUEST_LIST, MISSION_COUNT, MISSION_REQUEST_INT per item (answered
        with MISSION_ITEM_INT or, by older vehicles, MISSION_ITEM), then our MISSION_ACK; messages of another
        mission type are ignored. Returns sequence number -> item message. Raises CommandRefused (a MISSION_ACK
        with an error, named ``what``), BackendError / LinkLost."""
        got: dict[int, Any] = {}

        def begin() -> None:
            self._link.send(lambda mav: mav.mission_request_list_send(*self._link.target, mission_type))

        def request(seq: int) -> None:
            self._link.send(lambda mav: mav.mission_request_int_send(*self._link.target, seq, mission_type))

        def resend(last: Any) -> None:
            begin() if last is None else request(last)

        def on_msg(msg: Any, state: dict) -> bool:
            t = msg.get_type()
            if getattr(msg, "mission_type", 0) != mission_type:
                return False
            if t == "MISSION_COUNT" and "count" not in state:
                state["count"] = msg.count
                if msg.count == 0:
                    return True
                state["last"] = 0
                request(0)
            elif t in ("MISSION_ITEM_INT", "MISSION_ITEM") and "count" in state and msg.seq == state["last"]:
                got[msg.seq] = msg
                if msg.seq + 1 >= state["count"]:
                    return True
                state["last"] = msg.seq + 1
                request(msg.seq + 1)
            elif t == "MISSION_ACK" and msg.type != M.MAV_MISSION_ACCEPTED:
                raise CommandRefused(self.robot_id, what, _enum_name("MAV_MISSION_RESULT", msg.type),
                                     self._texts.since(state["start"]))
            return False

        self._transaction(what, begin, resend, on_msg)
        self._link.send(lambda mav: mav.mission_ack_send(*self._link.target, M.MAV_MISSION_ACCEPTED, mission_type))
        return got

    def held_plan_id(self, what: str) -> int:
        """The plan id of the mission the vehicle holds now, asked of it: MISSION_REQUEST_LIST, whose MISSION_COUNT
        carries it (``opaque_id``, :func:`~aerodaas.missionfile.plan_ids.plan_id`; 0: none given or no mission).
        Our MISSION_ACK then ends the download, also when no answer came: ACCEPTED for an empty one, else
        OPERATION_CANCELLED (mavlink.io mission protocol, "Canceling Operations"; PX4 returns to idle on either,
        ``MavlinkMissionManager::handle_mission_ack``, and until then refuses an upload on this link as busy). The
        answer is the vehicle's state after our request reached it, unlike a periodic report that may have been sent
        before; PX4 answers from the id all its links share (``_crc32``), so an upload over another link counts.
        Raises BackendError when ``command_retries`` + 1 requests of ``command_timeout_s`` s each go unanswered
        (named ``what``), LinkLost."""
        self._link.check_link(what)
        mission = M.MAV_MISSION_TYPE_MISSION
        state: dict[str, Any] = {}

        def begin() -> None:
            self._link.send(lambda mav: mav.mission_request_list_send(*self._link.target, mission))

        def on_msg(msg: Any, progress: dict) -> bool:
            if msg.get_type() == "MISSION_COUNT" and getattr(msg, "mission_type", 0) == mission:
                state["count"], state["plan_id"] = msg.count, plan_id(msg)
                return True
            return False

        def end() -> None:
            result = M.MAV_MISSION_ACCEPTED if state.get("count") == 0 else M.MAV_MISSION_OPERATION_CANCELLED
            self._link.send(lambda mav: mav.mission_ack_send(*self._link.target, result, mission))

        try:
            self._transaction(what, begin, lambda _last: begin(), on_msg)
        except BackendError:
            with contextlib.suppress(LinkLost):  # the error raised says more than a lost link here
                end()
            raise
        end()
        return state["plan_id"]

    def clear_mission(self) -> None:
        """MISSION_CLEAR_ALL; waits for MISSION_ACK. Raises CommandRefused / BackendError / LinkLost."""
        self._link.check_link("mission clear")

        def on_msg(msg: Any, state: dict) -> bool:
            if msg.get_type() == "MISSION_ACK":
                if msg.type != M.MAV_MISSION_ACCEPTED:
                    raise CommandRefused(self.robot_id, "mission clear", _enum_name("MAV_MISSION_RESULT", msg.type))
                return True
            return False

        clear = lambda *_: self._link.send(lambda mav: mav.mission_clear_all_send(*self._link.target, 0))  # noqa: E731
        self._transaction("mission clear", clear, clear, on_msg)

    # ------------------------------------------------------------------ typed transfers (fence, rally)
    def _require_mavlink2(self, what: str, mission_type: int) -> None:
        """``mission_type`` is a MAVLink 2 extension field: framed as MAVLink 1 it is dropped and the vehicle takes
        a fence for its mission (and overwrites the mission). Raises BackendError on a MAVLink 1 link."""
        if mission_type != M.MAV_MISSION_TYPE_MISSION and \
                self._link.wire_version != "2.0":
            raise BackendError(f"robot {self.robot_id!r}: {what}: the link speaks MAVLink 1, which cannot carry "
                               f"mission_type; the vehicle must send MAVLink 2 (ArduPilot SERIALn_PROTOCOL 2)")

    def upload_items(self, mission_type: int, wire: list[Wire]) -> None:
        """Upload ``wire`` as the vehicle's items of ``mission_type`` (MISSION_COUNT, each MISSION_REQUEST(_INT)
        answered with MISSION_ITEM_INT, until MISSION_ACK; all carrying ``mission_type``). An empty list clears
        them. Raises CommandRefused (MAV_MISSION_RESULT name), BackendError after ``command_retries`` timeouts,
        LinkLost."""
        what = f"{_TYPE_NAME.get(mission_type, mission_type)} upload"
        self._link.check_link(what)
        self._require_mavlink2(what, mission_type)
        n = len(wire)

        def send_item(seq: int) -> None:
            frame, cmd, p1, p2, p3, p4, xi, yi, z = wire[seq]
            self._link.send(lambda mav: mav.mission_item_int_send(*self._link.target, seq, frame, cmd, 0, 1,
                                                             p1, p2, p3, p4, xi, yi, z, mission_type))

        def resend(last: Any) -> None:
            if last is None:
                self._link.send(lambda mav: mav.mission_count_send(*self._link.target, n, mission_type))
            else:
                send_item(last)

        def on_msg(msg: Any, state: dict) -> bool:
            t = msg.get_type()
            if getattr(msg, "mission_type", 0) != mission_type:
                return False
            if t in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
                if 0 <= msg.seq < n:
                    state["last"] = msg.seq
                    state["max"] = max(state["max"], msg.seq)
                    send_item(msg.seq)
                return False
            if t == "MISSION_ACK":
                if msg.type == M.MAV_MISSION_INVALID_SEQUENCE and state["max"] < n - 1:
                    return False  # ArduPilot: an answer to a request it had already repeated (see mission.py)
                if msg.type != M.MAV_MISSION_ACCEPTED:
                    raise CommandRefused(self.robot_id, what, _enum_name("MAV_MISSION_RESULT", msg.type),
                                         self._texts.since(state["start"]))
                return state["max"] == n - 1 or n == 0
            return False

        self._transaction(what, lambda: resend(None), resend, on_msg)

    def download_items(self, mission_type: int) -> list[Wire]:
        """The vehicle's items of ``mission_type`` (MISSION_REQUEST_LIST, MISSION_COUNT, MISSION_REQUEST_INT per
        item, MISSION_ACK), as wire tuples ``(frame, command, param1..4, x, y, z)``. Raises CommandRefused,
        BackendError, LinkLost."""
        what = f"{_TYPE_NAME.get(mission_type, mission_type)} download"
        self._link.check_link(what)
        self._require_mavlink2(what, mission_type)
        got = self.download_messages(mission_type, what)
        out = []
        for seq in sorted(got):
            m = got[seq]
            x, y = (m.x, m.y) if m.get_type() == "MISSION_ITEM_INT" else (round(m.x * 1e7), round(m.y * 1e7))
            out.append((m.frame, m.command, _f32(m.param1), _f32(m.param2), _f32(m.param3), _f32(m.param4),
                        int(x), int(y), _f32(m.z)))
        return out
