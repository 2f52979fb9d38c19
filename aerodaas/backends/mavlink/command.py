"""The MAVLink command protocol (COMMAND_LONG -> COMMAND_ACK, retries, IN_PROGRESS, TEMPORARILY_REJECTED) and flight
mode changes confirmed by the HEARTBEAT. A concern object of :class:`~aerodaas.backends.mavlink.MavlinkBackend`."""
from __future__ import annotations

import queue
import time
from typing import Any, Callable

from aerodaas.backends.base import BackendError, CommandRefused, LinkLost
from aerodaas.backends.mavlink._common import M, _enum_name, CommandNotAcknowledged, CommandNotConfirmed, _REJECTED_BACKOFF_S
from aerodaas.backends.mavlink.clock import VehicleClock
from aerodaas.backends.mavlink.link import MavlinkLink
from aerodaas.backends.mavlink.statustext import StatusTexts


class CommandProtocol:
    """The MAVLink command protocol with one vehicle (COMMAND_LONG / COMMAND_INT -> COMMAND_ACK) and the commands
    whose effect the HEARTBEAT must show (mode changes, arming).

    It is given its collaborators: ``link`` (sending, the link check, the vehicle's system and component id, what
    the latest HEARTBEAT shows, MAV_CMD_DO_SET_MODE's params for a mode name), ``clock`` (the vehicle's latest
    time_boot_ms, whether a HEARTBEAT was due), ``texts`` (the autopilot's latest STATUSTEXT, for refusals) and
    ``event`` (records a backend event). ``settings``: ``command_timeout_s``, ``command_retries``,
    ``heartbeat_timeout_s``. It registers with the link (:meth:`MavlinkLink.serve_commands`): :meth:`on_command_ack`
    is fed every COMMAND_ACK for us (the I/O thread); commands wait for them (the control thread).

    State: the COMMAND_ACKs waiting to be taken, the round trips of acknowledged commands (:attr:`rtt_ms`) and our
    last mode request (:attr:`mode_asked`)."""

    def __init__(self, robot_id: str, settings: Any, *, link: MavlinkLink, clock: VehicleClock, texts: StatusTexts,
                 event: Callable[..., None]) -> None:
        self.robot_id, self._settings = robot_id, settings
        self._link, self._clock, self._texts, self._event = link, clock, texts, event
        #: acknowledged command round trips, wall milliseconds
        self.rtt_ms: list[float] = []
        self._acks: queue.Queue = queue.Queue()
        self._mode_asked: tuple[str, float] | None = None  # (mode, monotonic) of our last set_mode
        link.serve_commands(self)

    @property
    def mode_asked(self) -> tuple[str, float] | None:
        """(mode, monotonic seconds) of our last :meth:`set_mode`: a mode we asked for is never taken for the
        autopilot's failsafe (link.py ``_check_failsafe``)."""
        return self._mode_asked

    def on_command_ack(self, now: float, msg: Any) -> None:
        """A COMMAND_ACK addressed to us, received at monotonic ``now``: kept for the command waiting for it."""
        self._acks.put((now, msg))

    def command_long(self, name: str, command: int, *params: float, retries: int | None = None,
                     timeout_s: float | None = None) -> None:
        """Send COMMAND_LONG ``command`` (MAV_CMD number) with up to seven ``params`` and wait for its COMMAND_ACK
        (MAVLink command protocol). ``name`` is used in errors.

        Each try waits ``timeout_s`` (default ``command_timeout_s``) wall seconds from its own send for the ACK;
        without one the command is re-sent, up to ``retries`` (default ``command_retries``) times, with the
        ``confirmation`` counter raised, each time recorded as a ``command_resent`` event (``command``, ``attempt``,
        ``after``: "no COMMAND_ACK" or the previous try's MAV_RESULT name, ``waited_s``: wall seconds since the first
        send). The tries are counted, not fitted into a wall-clock budget (the MAVLink command protocol, "Command
        Protocol" on mavlink.io: re-send after a timeout, a set number of times): a stall of our own process (a
        loaded companion computer) never takes away the resends. An ACK received before a try's end is taken even
        when our thread reads it late. MAV_RESULT_TEMPORARILY_REJECTED ("retrying later should work", MAV_RESULT)
        uses a try too: re-sent after min(``timeout_s``, 0.5) s. After MAV_RESULT_IN_PROGRESS (the command runs;
        progress ACKs follow) the command is not sent again (MAVLink command protocol): its final ACK is awaited
        until (``retries`` + 1) x ``timeout_s`` from the first send, or that try's own end if later.

        Raises :class:`CommandRefused` (MAV_RESULT name, the autopilot's STATUSTEXT) for any final result but
        ACCEPTED, and for TEMPORARILY_REJECTED when the tries are used up; :class:`LinkLost` when the link is or
        goes down; :class:`BackendError` when no ACK comes, or the command is still IN_PROGRESS at the overall
        deadline."""
        self._link.check_link(name)
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        self._command_tries(name, command, lambda mav, attempt: mav.command_long_send(
            *self._link.target, command, min(attempt, 255), *p), retries, timeout_s)

    def command_int(self, name: str, command: int, frame: int, params: tuple[float, float, float, float], x: int,
                    y: int, z: float, retries: int | None = None, timeout_s: float | None = None) -> None:
        """Send COMMAND_INT ``command`` in MAV_FRAME ``frame`` (params 1-4; ``x``/``y`` latitude/longitude degrees
        x 1e7, ``z`` metres in the frame) and wait for its COMMAND_ACK, re-sent and refused as
        :meth:`command_long` (the MAVLink command protocol asks for COMMAND_INT for commands that carry a
        position). Raises what :meth:`command_long` raises."""
        self._link.check_link(name)
        p = [float(v) for v in params] + [0.0] * (4 - len(params))
        self._command_tries(name, command, lambda mav, attempt: mav.command_int_send(
            *self._link.target, frame, command, 0, 0, *p[:4], int(x), int(y), float(z)), retries, timeout_s)

    def _command_tries(self, name: str, command: int, send: Any, retries: int | None, timeout_s: float | None) -> None:
        """The tries of one command (:meth:`command_long`'s rules): ``send(mav, attempt)`` sends it once."""
        retries = self._settings.command_retries if retries is None else retries
        timeout = self._settings.command_timeout_s if timeout_s is None else timeout_s
        while True:  # drop acknowledgements nobody waited for
            try:
                self._acks.get_nowait()
            except queue.Empty:
                break
        started = time.monotonic()
        overall = started + (retries + 1) * timeout
        last: Any = None  # the latest non-final answer: IN_PROGRESS or TEMPORARILY_REJECTED
        answer: Any = None  # the non-final answer of the try before this one, if it had one
        for attempt in range(retries + 1):
            if attempt:  # on the record: the caller waited meanwhile (a tick of the drone may have waited too)
                self._event("command_resent", command=name, attempt=attempt,
                            after=_enum_name("MAV_RESULT", answer.result) if answer is not None else "no COMMAND_ACK",
                            waited_s=round(time.monotonic() - started, 3))
            sent = time.monotonic()
            self._link.send(lambda mav, attempt=attempt: send(mav, attempt))
            accepted, latest, answer = self._await_ack(name, command, started, sent, sent + timeout,
                                                       max(overall, sent + timeout), attempt == retries,
                                                       min(timeout, _REJECTED_BACKOFF_S))
            if accepted:
                return
            last = latest if latest is not None else last
            if last is not None and last.result == M.MAV_RESULT_IN_PROGRESS:
                break
        self._command_failed(name, command, last, started, retries, timeout)

    def _await_ack(self, name: str, command: int, started: float, sent: float, deadline: float, overall: float,
                   last_try: bool, backoff_s: float) -> tuple[bool, Any, Any]:
        """One try of :meth:`command_long`: wait for the COMMAND_ACK of ``command`` sent at ``sent`` until
        ``deadline`` (monotonic seconds); IN_PROGRESS moves that to ``overall`` (never re-sent), TEMPORARILY_REJECTED
        to at most ``backoff_s`` from now (or ends the try on the ``last_try``). The ACKs already received are read
        before the try ends, however late this thread runs. Returns (accepted, the try's latest non-final ACK, its
        latest TEMPORARILY_REJECTED ACK). Raises CommandRefused for a refusing final result, LinkLost when the link
        goes down."""
        latest: Any = None
        rejected: Any = None
        while True:
            remaining = deadline - time.monotonic()
            try:
                _, ack = self._acks.get(timeout=min(remaining, 0.05)) if remaining > 0 else self._acks.get_nowait()
            except queue.Empty:
                if remaining <= 0:
                    return False, latest, rejected
                if not self._link.link_ok:
                    raise LinkLost(f"robot {self.robot_id!r}: {name}: link lost while waiting for COMMAND_ACK")
                continue
            if ack.command != command:
                continue
            if ack.result == M.MAV_RESULT_ACCEPTED:
                self.rtt_ms.append((time.monotonic() - sent) * 1000.0)
                return True, latest, rejected
            if ack.result == M.MAV_RESULT_IN_PROGRESS:  # it runs: wait for the final ACK, never re-send
                latest = ack
                deadline = overall
                continue
            if ack.result == M.MAV_RESULT_TEMPORARILY_REJECTED:
                latest = rejected = ack
                if last_try:
                    return False, latest, rejected  # no try left to wait for
                deadline = min(deadline, time.monotonic() + backoff_s)
                continue
            raise CommandRefused(self.robot_id, name, _enum_name("MAV_RESULT", ack.result),
                                 self._texts.since(started))

    def _command_failed(self, name: str, command: int, last: Any, started: float, retries: int,
                        timeout: float) -> None:
        """Raise why :meth:`command_long` got no accepted COMMAND_ACK (``last``: the latest non-final one)."""
        if not self._link.link_ok:
            raise LinkLost(f"robot {self.robot_id!r}: {name}: link lost while waiting for COMMAND_ACK")
        if last is not None and last.result == M.MAV_RESULT_TEMPORARILY_REJECTED:
            raise CommandRefused(self.robot_id, name, "MAV_RESULT_TEMPORARILY_REJECTED",
                                 self._texts.since(started))
        if last is not None:
            progress = "" if last.progress in (0, 255) else f", progress {last.progress} %"
            raise BackendError(f"robot {self.robot_id!r}: {name}: {_enum_name('MAV_CMD', command)} still "
                               f"MAV_RESULT_IN_PROGRESS{progress} after {time.monotonic() - started:.1f} s (limit "
                               f"{retries + 1} x {timeout:g} s)")
        raise CommandNotAcknowledged(f"robot {self.robot_id!r}: {name}: no COMMAND_ACK for "
                                     f"{_enum_name('MAV_CMD', command)} after {retries + 1} tries of {timeout:g} s")

    def command_with_effect(self, name: str, effect: Callable[[], bool], *args: Any, **kw: Any) -> None:
        """:meth:`command_long` (``args``/``kw`` its own) whose effect the HEARTBEAT shows (``effect()``, e.g. the mode or the armed flag):
        when no COMMAND_ACK came at all (:class:`CommandNotAcknowledged`: answers lost, as seen on a loaded
        machine with three PX4 SITL instances, where PX4 armed but none of its acknowledgements arrived) but the
        HEARTBEAT shows the effect within ``heartbeat_timeout_s``, the command is done (``command_ack_lost``
        event); otherwise the error stands."""
        try:
            self.command_long(name, *args, **kw)
        except CommandNotAcknowledged:
            started, boot0 = time.monotonic(), self._clock.boot_ms
            while not effect() and not self._clock.heartbeat_due(started, boot0, self._settings.heartbeat_timeout_s) \
                    and self._link.link_ok:
                time.sleep(0.01)
            if not effect():
                raise
            self._event("command_ack_lost", command=name)

    # ------------------------------------------------------------------ modes
    def set_mode(self, name: str, confirm_s: float | None = None) -> None:
        """Switch to flight mode ``name`` (ArduPilot copter names ``GUIDED``, ``LAND``, ``RTL``, ``AUTO``,
        ``LOITER``...; PX4 names as pymavlink's ``px4_map``: ``OFFBOARD``, ``TAKEOFF``, ``LOITER``, ``MISSION``,
        ``RTL``, ``LAND``...) with MAV_CMD_DO_SET_MODE (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom main mode,
        PX4 sub mode), then wait up to ``confirm_s`` wall seconds (default the larger of ``command_timeout_s`` and
        ``heartbeat_timeout_s``) for a HEARTBEAT showing it. Raises ValueError for an unknown name,
        CommandRefused / LinkLost / BackendError as :meth:`command_long`, :class:`CommandNotConfirmed` (naming the
        mode asked for and the one the HEARTBEAT shows) when the vehicle acknowledged but never switched."""
        name = name.upper()
        sent = time.monotonic()
        self._mode_asked = (name, sent)  # a mode we asked for is never taken for the autopilot's failsafe
        params = self._link.mode_params(name)  # ValueError for a mode the autopilot does not have
        self.command_with_effect(f"set mode {name}", lambda: self._link.mode == name, M.MAV_CMD_DO_SET_MODE,
                                 M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, *params)
        self.await_heartbeat(f"set mode {name}", lambda: self._link.mode == name, f"mode {name}", confirm_s, sent)

    def await_heartbeat(self, command: str, done: Callable[[], bool], expected: str, wait_s: float | None,
                         sent: float) -> None:
        """After ``command`` (sent at monotonic ``sent``) was accepted: wait until ``done()`` (the HEARTBEAT shows
        ``expected``) for ``wait_s`` wall seconds (None: the larger of ``command_timeout_s`` and
        ``heartbeat_timeout_s``: the autopilot's HEARTBEAT comes at least that often while the link is up).
        Raises LinkLost or CommandNotConfirmed."""
        wait = max(self._settings.command_timeout_s, self._settings.heartbeat_timeout_s) if wait_s is None else wait_s
        started, boot0 = time.monotonic(), self._clock.boot_ms
        while not done():
            if not self._link.link_ok:
                raise LinkLost(f"robot {self.robot_id!r}: {command}: link lost before a HEARTBEAT showed {expected}")
            if self._clock.heartbeat_due(started, boot0, wait):
                hb = self._link
                observed = f"mode {hb.mode or '(none)'}, {'armed' if hb.armed else 'disarmed'}"
                raise CommandNotConfirmed(self.robot_id, command, expected, observed, wait,
                                          self._texts.since(sent, wait_s=0.0))
            time.sleep(0.005)
