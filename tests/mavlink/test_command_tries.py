"""The MAVLink command protocol's tries when our own process stalls (a loaded companion computer): the resends are
counted, not fitted into a wall-clock budget, and an ACK that arrived while our thread was held is taken.

The link is a stand-in that records each COMMAND_LONG and can hold the sending thread (as a starved thread is held),
so each case is decided by the number of sends and ACKs, whatever the machine's load."""
from __future__ import annotations

import time
from types import SimpleNamespace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from aerodaas.backends.mavlink import CommandNotAcknowledged
from aerodaas.backends.mavlink.command import CommandProtocol

TIMEOUT_S = 0.2


class _Mav:
    def __init__(self, link: "_StallingLink") -> None:
        self.link = link

    def command_long_send(self, target_system, target_component, command, confirmation, *params) -> None:
        self.link.sent.append((command, confirmation))
        self.link.on_send(command, len(self.link.sent))


class _StallingLink:
    """Records each send; ``stall_s`` holds the sender after its first send (longer than all tries' budget);
    ``ack_on_send`` answers MAV_RESULT_ACCEPTED to the given send (1-based) before the stall."""

    def __init__(self, stall_s: float, ack_on_send: int | None = None) -> None:
        self.sent: list[tuple[int, int]] = []
        self.stall_s, self.ack_on_send = stall_s, ack_on_send
        self.commands: CommandProtocol | None = None
        self.target = (1, 1)
        self.link_ok = True

    def serve_commands(self, commands: CommandProtocol) -> None:
        self.commands = commands

    def check_link(self, command: str) -> None:
        pass

    def send(self, fn) -> None:
        fn(_Mav(self))

    def on_send(self, command: int, n: int) -> None:
        if n == self.ack_on_send:
            self.commands.on_command_ack(time.monotonic(), SimpleNamespace(
                command=command, result=M.MAV_RESULT_ACCEPTED, progress=0))
        if n == 1:
            time.sleep(self.stall_s)


def _protocol(link: _StallingLink, retries: int) -> tuple[CommandProtocol, list[dict]]:
    events: list[dict] = []
    settings = SimpleNamespace(command_timeout_s=TIMEOUT_S, command_retries=retries, heartbeat_timeout_s=1.0)
    texts = SimpleNamespace(since=lambda started, wait_s=0.3: "")
    proto = CommandProtocol("d1", settings, link=link, clock=None, texts=texts,
                            event=lambda kind, **kw: events.append({"event": kind, **kw}))
    return proto, events


def test_a_stalled_first_send_still_gets_every_resend():
    """The first send holds our thread past every try's end: the command is still sent retries + 1 times, each
    resend on the record, before the error says no ACK came."""
    link = _StallingLink(stall_s=(2 + 1) * TIMEOUT_S * 1.5)
    proto, events = _protocol(link, retries=2)
    with pytest.raises(CommandNotAcknowledged, match="after 3 tries"):
        proto.command_long("arm", M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert [c for c, _ in link.sent] == [M.MAV_CMD_COMPONENT_ARM_DISARM] * 3
    assert [conf for _, conf in link.sent] == [0, 1, 2]
    assert [e["attempt"] for e in events if e["event"] == "command_resent"] == [1, 2]


def test_an_ack_received_while_our_thread_was_held_is_taken():
    """The vehicle accepts at once, but our thread reads the queue only after the try's end: the ACK is taken,
    nothing is re-sent and the round trip is kept."""
    link = _StallingLink(stall_s=2 * TIMEOUT_S, ack_on_send=1)
    proto, events = _protocol(link, retries=0)
    proto.command_long("arm", M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert len(link.sent) == 1
    assert not [e for e in events if e["event"] == "command_resent"]
    assert len(proto.rtt_ms) == 1
