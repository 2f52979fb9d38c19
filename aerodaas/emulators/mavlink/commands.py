"""The MAVLink command protocol (COMMAND_LONG / COMMAND_INT -> COMMAND_ACK; mavlink.io/en/services/command.html)
and the legacy SET_MODE message; result codes from PX4 ``Commander::handle_command`` (refusals are
TEMPORARILY_REJECTED) and ArduPilot ``GCS_MAVLINK`` (refusals are FAILED)."""
from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerodaas.emulators.mavlink.arming import Arming
from aerodaas.emulators.mavlink.constants import _IN_PROGRESS_PERIOD_S
from aerodaas.emulators.mavlink.gimbal import EmulatedGimbal
from aerodaas.emulators.mavlink.link import EmulatorLink
from aerodaas.emulators.mavlink.mission import MissionProtocol
from aerodaas.emulators.mavlink.mission_run import MissionRunner
from aerodaas.emulators.mavlink.modes import FlightModes
from aerodaas.emulators.mavlink.motion import Motion
from aerodaas.emulators.mavlink.state import EmulatorState
from aerodaas.emulators.mavlink.telemetry import Telemetry

if TYPE_CHECKING:
    from aerodaas.emulators.mavlink.link import _Link

M = mavlink

__all__ = ["CommandHandler"]


class CommandHandler:
    """Answers the commands the vehicle receives on ``link``: each MAV_CMD goes to the concern that carries it out
    (``arming``, ``modes``, ``telemetry``'s streams, the mission ``runner`` and ``protocol``, ``motion``'s speed,
    the ``gimbal``) over ``state``. Test hooks: ``ignore_commands`` (MAV_CMD numbers never acknowledged),
    ``ack_only_commands`` (acknowledged ACCEPTED but not carried out), ``in_progress_commands`` (answered
    MAV_RESULT_IN_PROGRESS every 0.5 vehicle seconds, never finished), :meth:`reject_next`. ``deny_default_speed``:
    MAV_CMD_DO_CHANGE_SPEED with a speed <= 0 is DENIED (None: as the flavour's firmware, ArduCopter denies, PX4
    accepts). :attr:`seen`: every MAV_CMD received. Not locked: the vehicle calls it under its lock."""

    def __init__(self, state: EmulatorState, link: EmulatorLink, telemetry: Telemetry, arming: Arming,
                 modes: FlightModes, motion: Motion, runner: MissionRunner, protocol: MissionProtocol,
                 gimbal: EmulatedGimbal, *, ignore_commands: set[int] | None = None,
                 ack_only_commands: set[int] | None = None, in_progress_commands: set[int] | None = None,
                 deny_default_speed: bool | None = None) -> None:
        self.state, self.link, self.telemetry, self.arming = state, link, telemetry, arming
        self.modes, self.motion, self.runner, self.protocol, self.gimbal = modes, motion, runner, protocol, gimbal
        self.store = protocol.store
        self.ignore_commands = set(ignore_commands or ())
        self.ack_only_commands = set(ack_only_commands or ())
        self.in_progress_commands = set(in_progress_commands or ())
        self.deny_default_speed = (not state.px4) if deny_default_speed is None else bool(deny_default_speed)
        self._enc = link.enc
        self._rejections: dict[int, list[int]] = {}  # MAV_CMD -> results still to answer (reject_next)
        self._in_progress: dict[int, tuple[_Link, int, int, float, int]] = {}  # cmd -> (link, sys, comp, next t, %)
        #: every MAV_CMD received (COMMAND_LONG and COMMAND_INT), in order
        self.seen: list[int] = []

    def in_progress_tick(self) -> None:
        """Per physics step: repeat MAV_RESULT_IN_PROGRESS for ``in_progress_commands``, its progress creeping
        towards 99 % (never done); forget those whose link closed."""
        t = self.state.t
        for cmd, (link, sysid, compid, due, pct) in list(self._in_progress.items()):
            if link not in self.link.peers:
                del self._in_progress[cmd]
            elif t >= due:  # COMMAND_ACK.progress creeps towards 99 %, never done
                pct = min(99, pct + 1)
                self._in_progress[cmd] = (link, sysid, compid, t + _IN_PROGRESS_PERIOD_S, pct)
                self.link.send(self._enc.command_ack_encode(cmd, M.MAV_RESULT_IN_PROGRESS, pct, 0, sysid, compid), link)

    def reject_next(self, command: int, count: int = 1,
                    result: int = M.MAV_RESULT_TEMPORARILY_REJECTED) -> None:
        """Answer the next ``count`` COMMAND_LONG/COMMAND_INT ``command`` (MAV_CMD number) with ``result``
        (MAV_RESULT, default TEMPORARILY_REJECTED: "try again later") without carrying it out. Raises ValueError
        for count < 1 or MAV_RESULT_ACCEPTED / IN_PROGRESS (see ``ack_only_commands`` / ``in_progress_commands``)."""
        if count < 1 or result in (M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS, M.MAV_RESULT_ENUM_END) \
                or result not in M.enums["MAV_RESULT"]:
            raise ValueError(f"reject_next: count must be >= 1 and result a refusing MAV_RESULT, got {count!r}, "
                             f"{result!r}")
        self._rejections.setdefault(int(command), []).extend([int(result)] * int(count))

    def on_command_long(self, link: _Link, msg: Any) -> None:
        """COMMAND_LONG: :meth:`_command` with its seven float params."""
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
        self._command(link, msg, msg.command, p)

    def on_command_int(self, link: _Link, msg: Any) -> None:
        """COMMAND_INT: :meth:`_command` with x/y as degrees (1e-7 deg on the wire), z and the frame."""
        p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.x / 1e7, msg.y / 1e7, msg.z]
        self._command(link, msg, msg.command, p, frame=msg.frame)

    def _command(self, link: _Link, msg: Any, cmd: int, p: list[float], frame: int | None = None) -> None:
        """Answer ``cmd`` from ``link`` as the test hooks or the firmware say (COMMAND_ACK to the sender)."""
        self.seen.append(cmd)
        if cmd in self.ignore_commands:
            return
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if cmd in self.in_progress_commands:  # repeated by in_progress_tick until the end of time
            prev = self._in_progress.get(cmd)
            self._in_progress[cmd] = (link, *src, self.state.t + _IN_PROGRESS_PERIOD_S, prev[4] if prev else 0)
            result = M.MAV_RESULT_IN_PROGRESS
        elif self._rejections.get(cmd):
            result = self._rejections[cmd].pop(0)
            if result == M.MAV_RESULT_TEMPORARILY_REJECTED:
                self.link.text(M.MAV_SEVERITY_WARNING, "Command temporarily rejected: busy")
        elif cmd in self.ack_only_commands:
            result = M.MAV_RESULT_ACCEPTED
        else:
            result = self._execute(link, cmd, p, frame)
        if result is None:
            return
        self.link.send(self._enc.command_ack_encode(cmd, result, 0, 0, *src), link)

    def _execute(self, link: _Link, cmd: int, p: list[float], frame: int | None) -> int | None:
        """Run COMMAND_LONG/_INT ``cmd`` with params ``p``: its MAV_RESULT, or None when the answer was sent here
        (a requested message follows its ACK)."""
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            return self.arming.arm_disarm(p)
        if cmd == M.MAV_CMD_DO_SET_MODE:
            if not int(p[0]) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                return M.MAV_RESULT_UNSUPPORTED if self.state.px4 else M.MAV_RESULT_FAILED
            return self.modes.request_mode(self.modes.mode_from_custom(int(p[1]), int(p[2])))
        if cmd == M.MAV_CMD_NAV_TAKEOFF:
            return self.modes.takeoff_command(p)
        if cmd == M.MAV_CMD_NAV_LAND:
            return self.modes.request_mode("AUTO.LAND" if self.state.px4 else "LAND")
        if cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return self.modes.request_mode("AUTO.RTL" if self.state.px4 else "RTL")
        if cmd == M.MAV_CMD_DO_CHANGE_SPEED:
            return self._change_speed(p)
        if cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self.telemetry.set_message_interval(p)
        if cmd in (M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_GET_HOME_POSITION, M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = {M.MAV_CMD_GET_HOME_POSITION: M.MAVLINK_MSG_ID_HOME_POSITION,
                      M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: M.MAVLINK_MSG_ID_AUTOPILOT_VERSION}.get(cmd, int(p[0]))
            out = self.telemetry.build(msg_id)
            if out is None:
                return M.MAV_RESULT_FAILED if msg_id == M.MAVLINK_MSG_ID_HOME_POSITION else M.MAV_RESULT_DENIED
            self.link.send(self._enc.command_ack_encode(cmd, M.MAV_RESULT_ACCEPTED, 0, 0, 0, 0), link)
            self.link.send(out, link)
            return None
        if cmd == M.MAV_CMD_MISSION_START:
            return self.runner.mission_start(int(p[0]) if p[0] == p[0] else 0)
        if cmd == M.MAV_CMD_DO_SET_MISSION_CURRENT:
            seq = int(p[0])
            if not 0 <= seq < len(self.store.mission):
                return M.MAV_RESULT_DENIED
            self.protocol.set_current(seq)
            return M.MAV_RESULT_ACCEPTED
        rel = M.MAV_FRAME_GLOBAL_RELATIVE_ALT if frame is None else frame
        gimbal = self.gimbal.command(cmd, p, functools.partial(self.state.global_to_enu, frame=rel))
        return M.MAV_RESULT_UNSUPPORTED if gimbal is None else gimbal

    def _change_speed(self, p: list[float]) -> int:
        """MAV_CMD_DO_CHANGE_SPEED (param1 speed type, param2 m/s): its MAV_RESULT."""
        if self.deny_default_speed:
            # ArduCopter/GCS_MAVLink_Copter.cpp handle_MAV_CMD_DO_CHANGE_SPEED: a speed that is not positive
            # (-1 "no change", -2 "default") is DENIED; climb/descent speeds (param1 2/3) change those rates
            if not p[1] > 0 or int(p[0]) not in (0, 1, 2, 3):
                return M.MAV_RESULT_DENIED
            if int(p[0]) in (0, 1):
                self.state.speed = float(p[1])
        elif p[1] == -2:  # PX4 Navigator: -2 restores the default cruise speed
            self.state.speed = None
        elif p[1] > 0:
            self.state.speed = float(p[1])
        elif p[1] != -1:
            return M.MAV_RESULT_DENIED
        self.motion.apply_speed_params()  # the leg being flown changes speed too
        return M.MAV_RESULT_ACCEPTED

    def on_set_mode(self, link: _Link, msg: Any) -> None:
        """SET_MODE (legacy, no answer): a custom mode for this system is requested (:meth:`.modes.FlightModes.request_mode`)."""
        if msg.target_system not in (0, self.link.system_id) or not msg.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return
        cm = msg.custom_mode
        if self.state.px4:
            self.modes.request_mode(self.modes.mode_from_custom((cm >> 16) & 0xFF, (cm >> 24) & 0xFF))
        else:
            self.modes.request_mode(self.modes.mode_from_custom(cm))
