"""Replay of real logs: duplicates are found per sender by sequence number in a short window (not by payload: at high
rates the 8-bit sequence wraps within the old 0.5 s window, and a repeated STATUSTEXT is a new message), a disarm
ends the armed states, and a log without battery data replays an unknown battery, not 100 %. The logs are written
here with pymavlink, packet by packet, in the tlog format (8-byte big-endian µs time + the packet)."""
from __future__ import annotations

import struct

import pytest

from aerodaas.backends import make_backend
from aerodaas.backends.flight_log import load_tlog
from aerodaas.config import ReplayConfig, RobotConfig

pytestmark = pytest.mark.faults

T0_US = 1_700_000_000_000_000
ARMED = 128


def write_tlog(path, packets) -> None:
    """``packets``: (time s, message, copies) written ``copies`` times each (byte-identical copies = a second link)."""
    from pymavlink.dialects.v20 import ardupilotmega as mav

    link = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    with open(path, "wb") as f:
        for t, msg, copies in packets:
            buf = msg.pack(link, force_mavlink1=False)
            link.seq = (link.seq + 1) % 256  # what MAVLink.send() does after packing
            for _ in range(copies):
                f.write(struct.pack(">Q", T0_US + int(t * 1e6)) + buf)


def _mav():
    from pymavlink.dialects.v20 import ardupilotmega as mav

    return mav


def hb(armed: bool):
    mav = _mav()
    return mav.MAVLink_heartbeat_message(2, 3, ARMED | 1 if armed else 1, 4, 4 if armed else 3, 3)


def gpos(t: float, alt_m: float = 0.0):
    return _mav().MAVLink_global_position_int_message(int(t * 1000), 473977000, 85456000, int((488 + alt_m) * 1000),
                                                      int(alt_m * 1000), 0, 0, 0, 0)


def test_duplicates_by_sequence_number_not_payload(tmp_path):
    mav = _mav()
    pk = [(0.0, hb(False), 1), (0.0, gpos(0.0), 1)]
    att = mav.MAVLink_attitude_message(1000, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0)
    # 600 byte-identical-payload ATTITUDE packets at 1 kHz: the sequence number wraps after 256, within 0.5 s
    pk += [(0.01 + i * 0.001, att, 1) for i in range(600)]
    # 20 packets captured twice (a second link): same sequence number, same message
    pk += [(1.0 + i * 0.01, gpos(1.0 + i * 0.01), 2) for i in range(20)]
    # the same STATUSTEXT sent twice by the autopilot: two messages
    txt = mav.MAVLink_statustext_message(4, b"Low battery")
    pk += [(2.0, txt, 1), (2.1, txt, 1)]
    f = tmp_path / "dups.tlog"
    write_tlog(f, pk)
    msgs, info = load_tlog(f)
    kinds = [m.type for m in msgs]
    assert kinds.count("ATTITUDE") == 600  # none lost to the wrap
    assert kinds.count("STATUSTEXT") == 2
    assert kinds.count("GLOBAL_POSITION_INT") == 21 and info["duplicates"] == 20


def _replay(path):
    from aerodaas.actors.drone.component import DroneComponent

    cfg = RobotConfig(id="px4", backend="replay", replay=ReplayConfig(log=str(path), rate=1.0))
    b = make_backend(cfg)
    d = DroneComponent("px4/drone", cfg.model_dump(mode="json"), None, None, None, 0, 0, [], [], backend=b)
    d.connect()
    b._t_wall0 = None  # drive the log clock by hand, not by wall time: step to each time in turn
    d.start()
    return b, d


def _play(b, d, until: float, dt: float = 0.05) -> list:
    states, t = [], 0.0
    while t <= until:
        b._t_applied = t
        b._t_wall0 = None
        b.step(0.0)  # applies the messages up to t (its clock reads _t_applied while _t_wall0 is None)
        d.control_tick()
        states.append(d.fsm.state.value)
        t += dt
    return states


def test_disarm_ends_the_armed_states(tmp_path):
    pk = [(0.0, hb(False), 1), (0.0, gpos(0.0), 1)]
    pk += [(1.0 + 0.5 * i, hb(True), 1) for i in range(4)]  # armed 1.0-2.5 s, never took off
    pk += [(3.0 + 0.5 * i, hb(False), 1) for i in range(4)]  # disarmed
    pk += [(5.0 + 0.5 * i, hb(True), 1) for i in range(2)]  # armed again: a second flight may start
    f = tmp_path / "arm.tlog"
    write_tlog(f, pk)
    b, d = _replay(f)
    states = _play(b, d, 6.0)
    i_arm = states.index("ARMED")
    assert "IDLE" in states[i_arm:], states  # the disarm left ARMED
    assert states[-1] == "ARMED"


def test_unknown_battery_is_unknown_not_100(tmp_path):
    mav = _mav()
    pk = [(0.0, hb(False), 1), (0.0, gpos(0.0), 1)]
    pk += [(0.5 * i, mav.MAVLink_sys_status_message(0, 0, 0, 0, 15800, -1, -1, 0, 0, 0, 0, 0, 0), 1)
           for i in range(4)]
    pk += [(0.5 * i, mav.MAVLink_battery_status_message(0, 0, 0, 0, [65535] * 10, -1, 0, 0, -1), 1)
           for i in range(4)]
    f = tmp_path / "nobat.tlog"
    write_tlog(f, pk)
    b = make_backend(RobotConfig(id="r", backend="replay", replay=ReplayConfig(log=str(f), rate=100.0)))
    b.connect()
    b._t_wall0 = None
    b._t_applied = 5.0
    b.step(0.0)
    assert b.state().battery_pct is None
    o = b.telemetry.odometry()
    assert o.battery_pct is None and o.model_dump(mode="json")["battery_pct"] is None
    assert b._volt == pytest.approx(15.8)
