"""Run inside the firmware's network namespace by tests/firmware/test_sitl_gimbal.py: points a real ArduCopter SITL's mount
with :class:`aerodaas.backends.mavlink.gimbal.GimbalManager` (gimbal protocol v2) and reports, as JSON on stdout,
what the firmware's own GIMBAL_DEVICE_ATTITUDE_STATUS said, beside what our geometry predicts.

    python tests/firmware/sitl_gimbal_probe.py CONNECTION
"""
from __future__ import annotations

import json
import math
import sys
import time

from pymavlink import mavutil

from aerodaas.backends.mavlink.gimbal import GimbalManager
from aerodaas.navigation.gimbal import roi_angles, wrap_deg

M = mavutil.mavlink


def main() -> int:
    conn = mavutil.mavlink_connection(sys.argv[1], source_system=255, source_component=190)
    conn.wait_heartbeat(timeout=120)
    sysid = conn.target_system
    sent: list[tuple[int, list[float]]] = []
    state: dict = {}

    def pump(until: float) -> None:
        while time.monotonic() < until:
            msg = conn.recv_match(blocking=True, timeout=0.2)
            if msg is None or msg.get_srcSystem() != sysid:
                continue
            kind = msg.get_type()
            if kind == "COMMAND_ACK":
                state.setdefault("acks", []).append((int(msg.command), int(msg.result)))
            elif kind == "GLOBAL_POSITION_INT":
                state["pos"] = msg
            elif kind == "ATTITUDE":
                state["att"] = msg
            elif kind == "STATUSTEXT" and "origin set" in msg.text:
                state["origin"] = True
            manager.on_message(msg, time.monotonic())

    def send(name: str, command: int, *params: float) -> None:
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        sent.append((command, p))
        transmit(name, command, lambda: conn.mav.command_long_send(sysid, 1, command, 0, *p))

    def send_int(name: str, command: int, frame: int, params: tuple, x: int, y: int, z: float) -> None:
        sent.append((command, [*params, x, y, z]))
        transmit(name, command, lambda: conn.mav.command_int_send(sysid, 1, frame, command, 0, 0, *params, x, y, z))

    def transmit(name: str, command: int, put) -> None:
        state["acks"] = []
        for _ in range(5):
            put()
            end = time.monotonic() + 2.0
            while time.monotonic() < end:
                pump(time.monotonic() + 0.2)
                got = [r for c, r in state.get("acks", []) if c == command]
                if got:
                    if got[-1] != M.MAV_RESULT_ACCEPTED:
                        raise RuntimeError(f"{name} refused: result {got[-1]}")
                    return
        raise RuntimeError(f"{name}: no COMMAND_ACK")

    manager = GimbalManager(send, send_int)
    for msg_id, hz in ((285, 10), (280, 1), (33, 10), (30, 10)):
        send("SET_MESSAGE_INTERVAL", 511, msg_id, 1e6 / hz)

    def wait_attitude(pitch: float, yaw: float, deadline_s: float = 60.0) -> dict:
        end = time.monotonic() + deadline_s
        while time.monotonic() < end:
            pump(time.monotonic() + 0.3)
            a = manager.attitude
            if a is not None and abs(a.pitch_deg - pitch) < 1.0 and abs(wrap_deg(a.yaw_deg - yaw)) < 1.0:
                break
        a = manager.attitude
        return {"pitch_deg": a.pitch_deg, "yaw_deg": a.yaw_deg, "earth": a.yaw_in_earth_frame} if a else {}

    out: dict = {}
    pump(time.monotonic() + 3.0)
    out["vehicle_limits"] = manager.vehicle_limits.model_dump() if manager.vehicle_limits else None
    manager.point(-45.0, 30.0)
    out["pitchyaw"] = {"asked": [-45.0, 30.0], "reported": wait_attitude(-45.0, 30.0)}
    n_sent = len(sent)
    try:
        manager.point(-100.0, 0.0)
        out["beyond_limit"] = "sent"
    except ValueError as e:
        out["beyond_limit"] = str(e)
    out["sent_after_refusal"] = len(sent) - n_sent
    # a region of interest 40 m north, 30 m east and 25 m below the vehicle: the firmware points the mount itself,
    # from its own position: wait for one (GLOBAL_POSITION_INT reads 0 N 0 E until the EKF has a GPS origin)
    end = time.monotonic() + 240.0
    while time.monotonic() < end and not (state.get("pos") and state["pos"].lat != 0 and state.get("origin")):
        pump(time.monotonic() + 0.5)
    pos = state["pos"]
    lat, lon = pos.lat / 1e7, pos.lon / 1e7
    dn, de, down = 40.0, 30.0, 25.0
    roi_lat = lat + math.degrees(dn / 6378137.0)
    roi_lon = lon + math.degrees(de / (6378137.0 * math.cos(math.radians(lat))))
    rel_alt = pos.relative_alt / 1e3
    manager.point_at(roi_lat, roi_lon, rel_alt - down)
    yaw_enu = 90.0 - math.degrees(state["att"].yaw)
    pitch, yaw = roi_angles((0.0, 0.0, rel_alt), yaw_enu, (de, dn, rel_alt - down))
    out["roi"] = {"predicted": [pitch, yaw], "reported": wait_attitude(pitch, yaw), "vehicle_yaw_enu_deg": yaw_enu}
    manager.release()
    out["commands_sent"] = [c for c, _ in sent if c != 511]
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
