"""Run inside PX4's network namespace by the single-vehicle session (tests/firmware/sitl.py, the ``upload``
scenario, before the CLI's upload): AeroDaaS's MAVLink backend uploads a mission on PX4's API link, a second
ground station on PX4's ground-station link then uploads another one, and the backend's start must refuse, the
firmware's own MISSION_CURRENT reporting the other mission's id. Writes JSON to OUT.

    python -m tests.firmware.sitl_plan_id API_CONNECTION GCS_CONNECTION LAT LON ALT OUT
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from pymavlink import mavutil

from aerodaas.backends import BackendError
from aerodaas.backends.mavlink import MavlinkBackend
from aerodaas.config import parse_environment_config
from aerodaas.missionfile import MissionItem
from aerodaas.missionfile.plan_ids import plan_id

#: MAV_FRAME_GLOBAL_RELATIVE_ALT; NAV_TAKEOFF, NAV_WAYPOINT, NAV_LAND
_FRAME, _TAKEOFF, _WAYPOINT, _LAND = 3, 22, 16, 21


def _items(lat: float, lon: float, north_deg: float) -> list[tuple[int, float, float, float]]:
    """Take-off, one waypoint ``north_deg`` north of home, land there: (command, lat, lon, altitude m)."""
    return [(_TAKEOFF, lat, lon, 5.0), (_WAYPOINT, lat + north_deg, lon, 5.0), (_LAND, lat + north_deg, lon, 0.0)]


def _upload_as_ground_station(gcs: str, items: list[tuple[int, float, float, float]]) -> dict:
    """Upload ``items`` from another ground station (system 255) with pymavlink alone; its MISSION_ACK's plan id
    and the id of the first MISSION_CURRENT after it."""
    m = mavutil.mavlink_connection(gcs, source_system=255)
    m.wait_heartbeat(timeout=60)
    m.mav.mission_count_send(m.target_system, m.target_component, len(items), 0)
    ack = None
    end = time.monotonic() + 30.0
    while ack is None and time.monotonic() < end:
        msg = m.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], blocking=True, timeout=5)
        if msg is None:
            continue
        if msg.get_type() == "MISSION_ACK":
            ack = msg
            break
        cmd, lat, lon, alt = items[msg.seq]
        m.mav.mission_item_int_send(m.target_system, m.target_component, msg.seq, _FRAME, cmd, 0, 1, 0, 0, 0, 0,
                                    int(round(lat * 1e7)), int(round(lon * 1e7)), alt, 0)
    current = m.recv_match(type="MISSION_CURRENT", blocking=True, timeout=10)
    m.close()
    return {"ack_type": None if ack is None else ack.type, "ack_id": 0 if ack is None else plan_id(ack),
            "current_id": 0 if current is None else plan_id(current)}


def main() -> int:
    api, gcs, lat, lon, alt, out = sys.argv[1], sys.argv[2], *(float(v) for v in sys.argv[3:6]), Path(sys.argv[6])
    env = {"name": "p", "robots": [{"id": "uav", "backend": "mavlink", "home": {"lat": lat, "lon": lon, "alt": alt},
                                    "mavlink": {"connection": api, "autopilot": "px4"}}]}
    b = MavlinkBackend(parse_environment_config(env).robots[0])
    b.connect(180.0)
    ours = [MissionItem(seq=k + 1, command=c, frame=_FRAME, params=[0.0, 0.0, 0.0, 0.0, la, lo, z])
            for k, (c, la, lo, z) in enumerate(_items(lat, lon, 1e-4))]
    b.mission.upload(ours)
    uploaded = [e for e in b.drain_events() if e["event"] == "mission_uploaded"]
    theirs = _upload_as_ground_station(gcs, _items(lat, lon, 2e-4))
    try:
        b.mission.start()
        result = "started"
    except BackendError as e:
        result = str(e)
    b.close()
    out.write_text(json.dumps({"ours": uploaded[0]["mission_id"] if uploaded else None, "theirs": theirs,
                               "start": result}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
