"""MAVLink mission vocabulary (``common.xml``): the ``MAV_CMD`` and ``MAV_FRAME`` numbers the mission files use,
their names (:func:`command_name`, :func:`frame_name`), and the command and frame sets that decide what a file may
hold and what a drone can fly (:data:`MISSION_FRAMES`, :data:`PAYLOAD_COMMANDS`)."""
from __future__ import annotations


MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_NAV_LOITER_UNLIM = 17
MAV_CMD_NAV_LOITER_TIME = 19
MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_DO_JUMP = 177
MAV_CMD_DO_CHANGE_SPEED = 178
MAV_CMD_DO_SET_ROI_WPNEXT_OFFSET = 196
MAV_CMD_DO_SET_ROI_NONE = 197
MAV_CMD_DO_SET_CAM_TRIGG_DIST = 206

#: ``MissionItem.nav_kind`` of the navigation commands a drone follows in an uploaded mission
NAV_KINDS = {MAV_CMD_NAV_WAYPOINT: "waypoint", MAV_CMD_NAV_TAKEOFF: "takeoff", MAV_CMD_NAV_LAND: "land",
             MAV_CMD_NAV_RETURN_TO_LAUNCH: "rtl"}

MAV_FRAME_GLOBAL = 0
MAV_FRAME_MISSION = 2
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3

#: ``MissionItem.command`` of a verbatim ``.plan`` ComplexItem (MAVLink defines no command 0).
COMPLEX_ITEM_COMMAND = 0

_CMD_NAMES: dict[int, str] = {
    16: "NAV_WAYPOINT", 17: "NAV_LOITER_UNLIM", 18: "NAV_LOITER_TURNS", 19: "NAV_LOITER_TIME",
    20: "NAV_RETURN_TO_LAUNCH", 21: "NAV_LAND", 22: "NAV_TAKEOFF", 23: "NAV_LAND_LOCAL", 24: "NAV_TAKEOFF_LOCAL",
    25: "NAV_FOLLOW", 30: "NAV_CONTINUE_AND_CHANGE_ALT", 31: "NAV_LOITER_TO_ALT", 32: "DO_FOLLOW",
    33: "DO_FOLLOW_REPOSITION", 80: "NAV_ROI", 81: "NAV_PATHPLANNING", 82: "NAV_SPLINE_WAYPOINT",
    83: "NAV_ALTITUDE_WAIT", 84: "NAV_VTOL_TAKEOFF", 85: "NAV_VTOL_LAND", 92: "NAV_GUIDED_ENABLE",
    93: "NAV_DELAY", 94: "NAV_PAYLOAD_PLACE", 112: "CONDITION_DELAY", 113: "CONDITION_CHANGE_ALT",
    114: "CONDITION_DISTANCE", 115: "CONDITION_YAW", 176: "DO_SET_MODE", 177: "DO_JUMP", 178: "DO_CHANGE_SPEED",
    179: "DO_SET_HOME", 180: "DO_SET_PARAMETER", 181: "DO_SET_RELAY", 182: "DO_REPEAT_RELAY",
    183: "DO_SET_SERVO", 184: "DO_REPEAT_SERVO", 185: "DO_FLIGHTTERMINATION", 186: "DO_CHANGE_ALTITUDE",
    188: "DO_RETURN_PATH_START", 189: "DO_LAND_START", 190: "DO_RALLY_LAND", 191: "DO_GO_AROUND",
    192: "DO_REPOSITION", 193: "DO_PAUSE_CONTINUE", 194: "DO_SET_REVERSE", 195: "DO_SET_ROI_LOCATION",
    196: "DO_SET_ROI_WPNEXT_OFFSET", 197: "DO_SET_ROI_NONE", 198: "DO_SET_ROI_SYSID", 200: "DO_CONTROL_VIDEO",
    201: "DO_SET_ROI", 202: "DO_DIGICAM_CONFIGURE", 203: "DO_DIGICAM_CONTROL", 204: "DO_MOUNT_CONFIGURE",
    205: "DO_MOUNT_CONTROL", 206: "DO_SET_CAM_TRIGG_DIST", 207: "DO_FENCE_ENABLE", 208: "DO_PARACHUTE",
    211: "DO_GRIPPER", 212: "DO_AUTOTUNE_ENABLE", 213: "NAV_SET_YAW_SPEED", 214: "DO_SET_CAM_TRIGG_INTERVAL",
    220: "DO_MOUNT_CONTROL_QUAT", 223: "DO_ENGINE_CONTROL", 224: "DO_SET_MISSION_CURRENT", 300: "MISSION_START",
    400: "COMPONENT_ARM_DISARM", 530: "SET_CAMERA_MODE", 531: "SET_CAMERA_ZOOM", 532: "SET_CAMERA_FOCUS",
    1000: "DO_GIMBAL_MANAGER_PITCHYAW", 1001: "DO_GIMBAL_MANAGER_CONFIGURE", 2000: "IMAGE_START_CAPTURE",
    2001: "IMAGE_STOP_CAPTURE", 2003: "DO_TRIGGER_CONTROL", 2500: "VIDEO_START_CAPTURE",
    2501: "VIDEO_STOP_CAPTURE", 3000: "DO_VTOL_TRANSITION", 5000: "NAV_FENCE_RETURN_POINT",
    5001: "NAV_FENCE_POLYGON_VERTEX_INCLUSION", 5002: "NAV_FENCE_POLYGON_VERTEX_EXCLUSION",
    5003: "NAV_FENCE_CIRCLE_INCLUSION", 5004: "NAV_FENCE_CIRCLE_EXCLUSION", 5100: "NAV_RALLY_POINT",
}

_FRAME_NAMES: dict[int, str] = {
    0: "GLOBAL", 1: "LOCAL_NED", 2: "MISSION", 3: "GLOBAL_RELATIVE_ALT", 4: "LOCAL_ENU", 5: "GLOBAL_INT",
    6: "GLOBAL_RELATIVE_ALT_INT", 7: "LOCAL_OFFSET_NED", 8: "BODY_NED", 9: "BODY_OFFSET_NED",
    10: "GLOBAL_TERRAIN_ALT", 11: "GLOBAL_TERRAIN_ALT_INT", 12: "BODY_FRD", 20: "LOCAL_FRD", 21: "LOCAL_FLU",
}

#: Frames a mission item in a file may use: global (AMSL, relative to home, terrain) and MAV_FRAME_MISSION.
MISSION_FRAMES = frozenset({0, 2, 3, 5, 6, 10, 11})
_GLOBAL_FRAMES = frozenset({0, 3, 5, 6, 10, 11})
_AMSL_FRAMES = frozenset({0, 5})
_RELATIVE_FRAMES = frozenset({3, 6})
_TERRAIN_FRAMES = frozenset({10, 11})

#: Commands whose ``x``/``y``/``z`` are a position, read in the item's frame. ArduPilot stores a location, and so a
#: frame, for these only (``libraries/AP_Mission/AP_Mission.cpp``: ``AP_Mission::stored_in_location``; for any other
#: command ``mission_cmd_to_mavlink_int`` returns frame 0 and x/y/z 0, whatever was sent). PX4 accepts an item in a
#: global frame only for its position commands (``src/modules/mavlink/mavlink_mission.cpp``:
#: ``MavlinkMissionManager::parse_mavlink_mission_item``: NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TIME, NAV_LAND,
#: NAV_TAKEOFF, NAV_LOITER_TO_ALT, DO_SET_ROI(_LOCATION), NAV_VTOL_TAKEOFF/LAND ...; DO_CHANGE_SPEED,
#: NAV_RETURN_TO_LAUNCH and the other commands without a position only in ``MAV_FRAME_MISSION`` 2, else
#: ``MAV_MISSION_UNSUPPORTED``) and reads them back in the frame it stored (2 for those). This is ArduPilot's list.
POSITION_COMMANDS = frozenset({16, 17, 18, 19, 21, 22, 30, 31, 82, 84, 85, 92, 94, 179, 189, 191, 201})

#: Commands that only drive the camera, gimbal or region of interest and leave the flight path unchanged:
#: DO_SET_ROI_LOCATION 195, DO_SET_ROI_WPNEXT_OFFSET 196, DO_SET_ROI_NONE 197, DO_SET_ROI 201,
#: DO_DIGICAM_CONFIGURE 202, DO_DIGICAM_CONTROL 203, DO_MOUNT_CONFIGURE 204, DO_MOUNT_CONTROL 205,
#: DO_SET_CAM_TRIGG_DIST 206, DO_SET_CAM_TRIGG_INTERVAL 214, SET_CAMERA_MODE 530, SET_CAMERA_ZOOM 531,
#: SET_CAMERA_FOCUS 532, DO_GIMBAL_MANAGER_PITCHYAW 1000, DO_GIMBAL_MANAGER_CONFIGURE 1001,
#: IMAGE_START_CAPTURE 2000, IMAGE_STOP_CAPTURE 2001, DO_TRIGGER_CONTROL 2003, VIDEO_START_CAPTURE 2500,
#: VIDEO_STOP_CAPTURE 2501. AeroDaaS cameras stream continuously, so a caller may pass these as
#: ``plan_to_flight(..., skip_commands=PAYLOAD_COMMANDS)``; skipped items are reported, never hidden.
PAYLOAD_COMMANDS = frozenset({195, 196, 197, 201, 202, 203, 204, 205, 206, 214, 530, 531, 532, 1000, 1001,
                              2000, 2001, 2003, 2500, 2501})

#: Commands :func:`plan_to_flight` interprets itself (they cannot be skipped).
_FLIGHT_COMMANDS = frozenset({16, 17, 19, 20, 21, 22, 178})


def command_name(command: int) -> str:
    """``"MAV_CMD_NAV_LAND (21)"``; commands outside the table read ``"MAV_CMD 31000 (not in common.xml)"``."""
    if command == COMPLEX_ITEM_COMMAND:
        return "ComplexItem"
    name = _CMD_NAMES.get(command)
    return f"MAV_CMD_{name} ({command})" if name else f"MAV_CMD {command} (not in common.xml)"


def frame_name(frame: int) -> str:
    """``"MAV_FRAME_GLOBAL_RELATIVE_ALT (3)"``."""
    name = _FRAME_NAMES.get(frame)
    return f"MAV_FRAME_{name} ({frame})" if name else f"unknown MAV_FRAME {frame}"
