"""Follow a mission file flown by the firmware (``tests/firmware/test_sitl_mission_files.py``), judged from the
firmware's own telemetry on its *second* link (raw pymavlink, :class:`tests.firmware.sitl_fence.Watcher`, never AeroDaaS):

``python -m tests.firmware.sitl_mission follow CONN OUT LAT LON ALT LAST_SEQ RTL_AFTER``: wait until the vehicle arms (someone
else starts the mission: ``aerodaas mission upload --start``), then record until it has disarmed again (or 400 wall
seconds; 180 s without arming: the mission was not started) every MISSION_CURRENT change (``[t, seq]``), every MISSION_ITEM_REACHED (``[t, seq]``), GLOBAL_POSITION_INT
(``[t, east, north, relative alt, mode]``, ENU metres from LAT/LON/ALT), the modes and STATUSTEXTs. ``RTL_AFTER``
1: a mission without a terminal action (QGroundControl's square) ends hovering, so once the firmware reports wire
sequence ``LAST_SEQ`` reached the follower sends MAV_CMD_NAV_RETURN_TO_LAUNCH, and the vehicle lands at home. The
firmware's time (``time_boot_ms`` of the last position) stamps every record. Writes JSON to OUT.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from aerodaas.model.types import GeoPoint
from tests.firmware.sitl_fence import Watcher

MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MSG_MISSION_CURRENT = 42


def mission_file(path: Path, home: dict) -> Path:
    """A QGC WPL 110 mission written to ``path``: take off (at ``home``, a dict of lat/lon/alt) to 2 m, two waypoints
    6 m apart (the first at 2.004 m, hold 2.5 s: ArduCopter keeps 2 m and 2 s; the second at 2 m, hold 3 s), land
    (:func:`tests.firmware.sitl.single_vehicle_session`'s ``mission upload --start``)."""
    from aerodaas.model.geo import enu_to_geodetic

    h = GeoPoint(**home)
    a, b = enu_to_geodetic(0.0, 6.0, 0.0, h), enu_to_geodetic(6.0, 6.0, 0.0, h)
    rows = ["QGC WPL 110", f"0\t1\t0\t16\t0\t0\t0\t0\t{h.lat:.7f}\t{h.lon:.7f}\t{h.alt:.2f}\t1",
            f"1\t0\t3\t22\t0\t0\t0\t0\t{h.lat:.7f}\t{h.lon:.7f}\t2.0\t1",  # PX4 takes 0, 0 literally
            f"2\t0\t3\t16\t2.5\t0\t0\t0\t{a.lat:.7f}\t{a.lon:.7f}\t2.004\t1",
            f"3\t0\t3\t16\t3\t0\t0\t0\t{b.lat:.7f}\t{b.lon:.7f}\t2.0\t1",
            f"4\t0\t3\t21\t0\t0\t0\t0\t{b.lat:.7f}\t{b.lon:.7f}\t0\t1"]
    path.write_text("\n".join(rows) + "\n")
    return path


def follow(conn: str, out: str, home: GeoPoint, last_seq: int, rtl_after: bool, timeout_s: float = 400.0) -> int:
    w = Watcher(conn, home)
    w.wait_vehicle(120)
    w.m.mav.command_long_send(w.sysid, w.compid, MAV_CMD_SET_MESSAGE_INTERVAL, 0, MSG_MISSION_CURRENT, 5e5,
                              0, 0, 0, 0, 0)
    current: list[list] = []
    reached: list[list] = []
    rtl_sent = None
    end = time.monotonic() + timeout_s
    arming = time.monotonic() + 180.0  # a mission that was not started: no arming to wait for
    while time.monotonic() < end and not (w.was_armed and not w.armed) and (w.was_armed or time.monotonic() < arming):
        msg = w.pump(0.2, want=("MISSION_CURRENT", "MISSION_ITEM_REACHED"))
        if msg is None or not w.was_armed:
            continue
        if msg.get_type() == "MISSION_CURRENT":
            if not current or current[-1][1] != msg.seq:
                current.append([w.t_boot, msg.seq])
        else:
            if not reached or reached[-1][1] != msg.seq:
                reached.append([w.t_boot, msg.seq])
            if rtl_after and msg.seq == last_seq and rtl_sent is None:
                w.m.mav.command_long_send(w.sysid, w.compid, MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0, 0)
                rtl_sent = w.t_boot
    Path(out).write_text(json.dumps({
        "autopilot": w.autopilot, "current": current, "reached": reached, "rtl_sent": rtl_sent,
        "samples": w.samples, "modes": w.modes, "texts": w.texts, "was_armed": w.was_armed,
        "armed_at_end": w.armed}))
    return 0


if __name__ == "__main__":
    if sys.argv[1] == "follow":
        lat, lon, alt = map(float, sys.argv[4:7])
        sys.exit(follow(sys.argv[2], sys.argv[3], GeoPoint(lat=lat, lon=lon, alt=alt), int(sys.argv[7]),
                        sys.argv[8] == "1"))
    raise SystemExit(f"unknown command {sys.argv[1]!r}")
