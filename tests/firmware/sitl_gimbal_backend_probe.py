"""Run inside the firmware's network namespace by tests/firmware/test_sitl_gimbal.py: AeroDaaS's own MAVLink backend (the one
a drone actor holds, with a robot ``gimbal`` section) points a real ArduCopter SITL's mount through
``VehicleBackend.gimbal`` (``point``) and reads the firmware's GIMBAL_DEVICE_ATTITUDE_STATUS back through
``gimbal.drain``. Prints JSON on stdout.

    python tests/firmware/sitl_gimbal_backend_probe.py CONNECTION LAT LON ALT
"""
from __future__ import annotations

import json
import sys
import time

from aerodaas.backends.mavlink import MavlinkBackend
from aerodaas.config import parse_environment_config
from aerodaas.navigation.gimbal import roi_angles, wrap_deg
from aerodaas.protocol.gimbal import GimbalPoint, GimbalRelease, GimbalRoi

LIMITS = {"pitch_min_deg": -90, "pitch_max_deg": 20, "yaw_min_deg": -180, "yaw_max_deg": 180, "rate_deg_s": 60}


def main() -> int:
    conn, lat, lon, alt = sys.argv[1], *(float(v) for v in sys.argv[2:5])
    env = {"name": "g", "robots": [{"id": "uav", "backend": "mavlink", "home": {"lat": lat, "lon": lon, "alt": alt},
                                    "mavlink": {"connection": conn, "autopilot": "ardupilot"}, "gimbal": LIMITS}]}
    b = MavlinkBackend(parse_environment_config(env).robots[0])
    b.connect(180.0)
    reports: list = []
    texts: list[str] = []

    def wait(pitch: float, yaw: float, deadline_s: float = 60.0) -> dict:
        end = time.monotonic() + deadline_s
        while time.monotonic() < end:
            reports.extend(b.gimbal.drain())
            texts.extend(str(e.get("text", "")) for e in b.drain_events() if e.get("event") == "status_text")
            a = b.gimbal.latest()
            if a is not None and abs(a.pitch_deg - pitch) < 1.0 and abs(wrap_deg(a.yaw_deg - yaw)) < 1.0:
                break
            time.sleep(0.1)
        a = b.gimbal.latest()
        return {"pitch_deg": a.pitch_deg, "yaw_deg": a.yaw_deg, "earth": a.yaw_in_earth_frame,
                "q": list(a.q)} if a else {}

    out: dict = {}
    b.gimbal.point(GimbalPoint(-45.0, 30.0))
    out["pitchyaw"] = wait(-45.0, 30.0)
    end = time.monotonic() + 240.0  # the firmware points at a location only once its EKF has an origin
    while time.monotonic() < end and not any("origin set" in t for t in texts):
        texts.extend(str(e.get("text", "")) for e in b.drain_events() if e.get("event") == "status_text")
        reports.extend(b.gimbal.drain())
        time.sleep(0.2)
    time.sleep(2.0)
    pos, yaw_enu = tuple(float(c) for c in b.state().position), float(b.state().yaw)
    roi = (30.0, 40.0, pos[2] - 25.0)
    b.gimbal.point(GimbalRoi(*roi))
    pred = roi_angles(pos, yaw_enu, roi)
    out["roi"] = {"predicted": list(pred), "reported": wait(*pred), "position": list(pos), "yaw_enu": yaw_enu}
    b.gimbal.point(GimbalRelease())
    out["reports"] = len(reports)
    out["sources"] = sorted({r.source for r in reports})
    b.close()
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
