"""A flood of forged MAVLink messages in a signing vehicle's name does not starve its signed telemetry
(aerodaas/backends/mavlink/signing.py ``LinkSigning.screen``, shared_link.py ``LinkPort.screen``): on the emulated
ArduCopter, 20 times as many forged GLOBAL_POSITION_INT and ATTITUDE messages as it streams (half unsigned, half
signed with another key and a timestamp ten days ahead) on its own link. Count-based, never timed: every signed
message the vehicle sent is accepted, no forged one reaches the backend's dispatch (dropped before the robot's
queue), each is counted, and the events stay few. The telemetry age this costs is measured by
``python -m aerodaas.bench.signing_flood`` (docs/security.md, "Denial of service")."""
from __future__ import annotations

import time

from aerodaas.backends.mavlink.signing import FIRST_EVENTS
from aerodaas.bench.signing_flood import KEY, FloodSource, SignedTelemetryTap
from tests.mavlink.test_mavlink_signing import _key_file


def _wait(cond, timeout_s: float) -> bool:
    """Poll ``cond`` until true or ``timeout_s`` wall seconds (a bound on a hung test, never the assertion)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.05)
    return cond()


def test_under_a_forged_flood_every_signed_telemetry_message_is_accepted(fly, tmp_path):
    emu, b = fly("ardupilot", speedup=2.0, signing_key=KEY,
                 mavlink={"signing_key_file": _key_file(tmp_path / "v.key", KEY), "set_speed_limits": False,
                          "stream_rate_hz": 10.0})
    tap = SignedTelemetryTap(emu, b)
    reached_dispatch = []
    dispatch = b.link.dispatch

    def watched_dispatch(msg, now):  # what reached the backend's I/O thread through the robot's queue
        if msg.get_type() in ("ATTITUDE", "GLOBAL_POSITION_INT") and (
                getattr(msg, "roll", 0.0) == 3.0 or getattr(msg, "lat", 0) >= 890_000_000):
            reached_dispatch.append(msg.get_type())
        dispatch(msg, now)

    b.link.dispatch = watched_dispatch
    b.drain_events()
    tap.recording = True
    flood = FloodSource(emu, rate_hz=20 * 2 * 10.0 * 2.0)  # 20x GLOBAL_POSITION_INT + ATTITUDE at 10 Hz, 2x time
    flood.start()
    try:
        assert _wait(lambda: len(tap.sent) >= 100 and flood.count >= 2000, 120), (len(tap.sent), flood.count)
    finally:
        flood.stop.set()
        flood.join()
    tap.recording = False
    written = flood.count
    assert _wait(lambda: not tap.missing() and b.signing.unsigned + b.signing.bad_signature >= written, 60)
    assert tap.missing() == set(), sorted(tap.missing())[:10]  # every signed one sent in the flood was accepted
    assert tap.forged_accepted == 0 and reached_dispatch == []  # dropped before the queue, never dispatched
    assert b.signing.unsigned + b.signing.bad_signature == written  # each counted
    assert b.signing.unsigned > 0 and b.signing.bad_signature > 0
    assert b.link.port.dropped == 0
    b.signing.report(time.monotonic() + 60.0)  # a summary due
    events = [e for e in b.drain_events() if e["event"] in ("link_unsigned", "link_bad_signature")]
    one_each = [e for e in events if "message" in e]
    assert len(one_each) == 2 * FIRST_EVENTS, one_each  # the first five of each kind, then summaries only
    assert len(events) - len(one_each) <= 2 * (1 + 120 // 5 + 1), len(events)
