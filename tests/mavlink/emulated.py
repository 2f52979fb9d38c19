"""What the emulated-vehicle tests share: the homes, the firmware's refusal texts, and driving a backend like
the runtime does (:func:`run_until`)."""
from __future__ import annotations

import json
import time

import numpy as np
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M

from aerodaas.missionfile.plan_ids import plan_id
from aerodaas.model.types import GeoPoint

AUTOPILOTS = ["ardupilot", "px4"]
CONFIG_HOME = GeoPoint(lat=47.3977, lon=8.5456, alt=488.0)
VEHICLE_HOME = GeoPoint(lat=47.39797, lon=8.5456, alt=500.0)  # 30 m north of, 12 m above the configured home
RTL_PARAMS = {"ardupilot": {"RTL_ALT": 800.0}, "px4": {"RTL_RETURN_ALT": 8.0}}
REFUSED = {"ardupilot": "MAV_RESULT_FAILED", "px4": "MAV_RESULT_TEMPORARILY_REJECTED"}
PREARM_PREFIX = {"ardupilot": "Arm: ", "px4": "Preflight Fail: "}  # a refused arm command, as the firmware says


def replace_mission_on_read(emu, times: int, shift_last: bool = False) -> list[int]:
    """Make the emulated vehicle drop its mission (hold none) just before each of the first ``times`` mission
    downloads, as PX4 does when a mission state published meanwhile replaces the one just uploaded; with
    ``shift_last``, hold another mission instead: the same items, the last one's latitude 1e-5 degree (about 1 m)
    further north. Returns the list of mission lengths it replaced."""
    handler = emu.handlers["MISSION_REQUEST_LIST"]
    dropped: list[int] = []

    def replaced(link, msg):
        if getattr(msg, "mission_type", 0) == 0 and len(dropped) < times:
            with emu._lock:
                dropped.append(len(emu.missions.mission))
                if shift_last:
                    emu.missions.mission[-1].x += 100  # MISSION_ITEM_INT latitude, 1e-7 degree units
                else:
                    emu.missions.mission = []
        handler(link, msg)

    emu.handlers["MISSION_REQUEST_LIST"] = replaced
    return dropped


def replace_mission_on_arm(emu) -> list[int]:
    """Make the emulated vehicle hold another mission (the last item's latitude 1e-5 degree further north) when it
    is next asked to arm, as if another ground station had uploaded one; returns the mission lengths replaced."""
    handler = emu.handlers["COMMAND_LONG"]
    replaced: list[int] = []

    def arming(link, msg):
        if msg.command == M.MAV_CMD_COMPONENT_ARM_DISARM and msg.param1 == 1 and not replaced:
            with emu._lock:
                replaced.append(len(emu.missions.mission))
                emu.missions.mission[-1].x += 100
        handler(link, msg)

    emu.handlers["COMMAND_LONG"] = arming
    return replaced


def upload_as_another_station(address: str, lat: float, lon: float) -> int:
    """A second ground station (system 255, pymavlink alone) uploads a one-waypoint mission; its ACK's plan id."""
    m = mavutil.mavlink_connection(address, source_system=255)
    try:
        m.wait_heartbeat(timeout=10)
        m.mav.mission_count_send(m.target_system, m.target_component, 1, 0)
        while True:
            msg = m.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], blocking=True,
                               timeout=10)
            assert msg is not None, "no answer to the other station's upload"
            if msg.get_type() == "MISSION_ACK":
                assert msg.type == M.MAV_MISSION_ACCEPTED
                return plan_id(msg)
            m.mav.mission_item_int_send(m.target_system, m.target_component, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                                        M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0, int(lat * 1e7), int(lon * 1e7),
                                        30.0, 0)
    finally:
        m.close()


def run_until(backend, cond, timeout_s: float = 15.0, every=None) -> bool:
    """Drive the backend like the runtime does (step() at 20 Hz wall) until ``cond()``; ``every()`` each tick."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        backend.step(0.05)
        if every is not None:
            every()
        if cond():
            return True
        time.sleep(0.05)
    return False


def position_ready(backend) -> bool:
    """HOME_POSITION came and the autopilot's own reports say it can arm (its EKF has a position estimate).
    HOME_POSITION alone is not enough before a mode that needs a position (PX4 LOITER): PX4 sets home from a GPS
    fix before its estimator's global position is valid (commander HomePosition.cpp,
    ``can_set_home_gpos_first_time``), which the emulator models as ``ekf_gps_s`` vehicle seconds between the two."""
    return backend.telemetry.home_received and not backend.actions.not_ready_reasons()


def dist(a, b) -> float:
    return float(np.linalg.norm(np.asarray(a, float) - np.asarray(b, float)))


def with_max_speed(env_path, max_speed: float) -> None:
    """Rewrite the environment file ``env_path`` (a path) so its first robot flies at ``max_speed`` m/s: the farm
    survey's legs at the app's 0.5 m/s are most of its flight, where a test judges only how the flight starts or
    ends."""
    env = json.loads(env_path.read_text())
    env["robots"][0]["limits"]["max_speed"] = max_speed
    env_path.write_text(json.dumps(env))
