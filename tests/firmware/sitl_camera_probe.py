"""Run inside the firmware's network namespace by tests/firmware/test_sitl_camera.py: gives a real ArduCopter SITL a camera
(``CAM1_TYPE 1`` and ``SCR_ENABLE 1`` set with the parameter protocol, then a reboot: ``CAM1_TYPE`` in a defaults
file reads back 0 after boot), then connects with the MAVLink backend and discovers the camera's video stream (camera protocol v2)
as a camera with ``source: "mavlink"`` does; prints the :class:`aerodaas.video.discovery.DiscoveredStream` as JSON
on stdout. The stream itself is announced by a Lua script in the firmware's ``scripts/`` folder
(``camera:set_stream_information``, as ArduPilot's video-stream-information applet does).

    python tests/firmware/sitl_camera_probe.py CONNECTION TIMEOUT_S
"""
from __future__ import annotations

import dataclasses
import json
import sys
import time

from pymavlink import mavutil

from aerodaas.backends.mavlink import MavlinkBackend
from aerodaas.config import MavlinkConfig, RobotConfig
from aerodaas.video.discovery import StreamRequest


def give_camera(connection: str) -> None:
    """CAM1_TYPE 1 (servo-triggered camera), SCR_ENABLE 1 (Lua scripting) and a reboot: AP_Camera then has
    instance 0 and the script in the firmware's ``scripts/`` folder runs."""
    M = mavutil.mavlink
    c = mavutil.mavlink_connection(connection, source_system=255, source_component=190)
    c.wait_heartbeat(timeout=120)
    for name in ("CAM1_TYPE", "SCR_ENABLE"):
        end = time.monotonic() + 60
        while time.monotonic() < end:
            c.mav.param_set_send(c.target_system, 1, name.encode(), 1, M.MAV_PARAM_TYPE_INT8)
            got = c.recv_match(type="PARAM_VALUE", blocking=True, timeout=2)
            if got is not None and got.param_id == name and got.param_value == 1:
                break
        else:
            raise SystemExit(f"the firmware did not take {name} 1")
    c.mav.command_long_send(c.target_system, 1, M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 0, 1, 0, 0, 0, 0, 0, 0)
    c.close()
    time.sleep(5)  # the reboot's start: its first HEARTBEAT after it is what connect() waits for


def main() -> int:
    give_camera(sys.argv[1])
    b = MavlinkBackend(RobotConfig(id="quad", backend="mavlink",
                                   mavlink=MavlinkConfig(connection=sys.argv[1], connect_timeout_s=120)))
    b.connect()
    try:
        found = b.discover_video_stream(StreamRequest("quad", "cam1", timeout_s=float(sys.argv[2])))
    finally:
        b.close()
    print(json.dumps({**dataclasses.asdict(found), "stream_type": found.stream_type.name}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
