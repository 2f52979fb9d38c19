"""What differs between the emulated autopilots and is read from the firmware rather than the MAVLink spec: the
parameter defaults and units, the vehicle envelope they imply, SYS_STATUS sensor bits and the EKF status flags.

Every value here was observed on the real firmware with :mod:`.trace` (ArduCopter SITL at ArduPilot master
90700977, PX4 SIH at PX4-Autopilot main 02e73e3b6f; see ../shared/sitl/README.md) and comes from the source named
beside it."""
from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink

M = mavlink

#: ArduCopter parameters (name -> default, in the firmware's units). WPNAV_*: libraries/AC_WPNav/AC_WPNav.cpp
#: (WPNAV_SPEED 1000 cm/s, WPNAV_SPEED_UP 250 cm/s, WPNAV_SPEED_DN 150 cm/s, WPNAV_ACCEL 250 cm/s/s,
#: WPNAV_RADIUS 200 cm); RTL_ALT 1500 cm (ArduCopter/Parameters.cpp); LAND_SPEED 50 cm/s; DISARM_DELAY 10 s.
ARDUPILOT_PARAMS: dict[str, float] = {
    "RTL_ALT": 1500.0, "LAND_SPEED": 50.0, "WPNAV_SPEED": 1000.0, "WPNAV_SPEED_UP": 250.0,
    "WPNAV_SPEED_DN": 150.0, "WPNAV_ACCEL": 250.0, "WPNAV_RADIUS": 200.0, "DISARM_DELAY": 10.0,
    # AC_Fence (libraries/AC_Fence/AC_Fence.cpp): disabled, all three types, 100 m, RTL or land; FENCE_RADIUS 150 m
    # is SITL's copter.parm (the library default is 300); FENCE_OPTIONS 0 (inclusion zones intersect)
    "FENCE_ENABLE": 0.0, "FENCE_TYPE": 7.0, "FENCE_ALT_MAX": 100.0, "FENCE_ACTION": 1.0, "FENCE_RADIUS": 150.0,
    "FENCE_OPTIONS": 0.0,
    # SITL's engine failure (libraries/SITL/SITL.cpp): the PWM of the motors in the SIM_ENGINE_FAIL bitmask (bit 0:
    # servo 1) is scaled by SIM_ENGINE_MUL (default 0, applied to no motor); SIM_Aircraft.cpp applies it
    "SIM_ENGINE_MUL": 0.0, "SIM_ENGINE_FAIL": 0.0,
}
#: PX4 parameters (name -> default, SI units). MPC_*: src/modules/mc_pos_control/multicopter_*_params.c
#: (MPC_XY_CRUISE 5 m/s, MPC_XY_VEL_MAX 12 m/s, MPC_Z_VEL_MAX_UP 3 m/s, MPC_Z_VEL_MAX_DN 1.5 m/s,
#: MPC_ACC_HOR 3 m/s/s, MPC_LAND_SPEED 0.7 m/s); navigator: NAV_ACC_RAD 2 m, MIS_TAKEOFF_ALT 2.5 m,
#: RTL_RETURN_ALT 30 m, RTL_DESCEND_ALT 10 m (multicopter defaults, ROMFS rc.mc_defaults); commander: COM_OF_LOSS_T, COM_DISARM_PRFLT 10 s,
#: COM_DISARM_LAND 2 s, COM_HOME_EN 1.
PX4_PARAMS: dict[str, float] = {
    "RTL_RETURN_ALT": 30.0, "RTL_DESCEND_ALT": 10.0, "MPC_LAND_SPEED": 0.7, "MIS_TAKEOFF_ALT": 2.5,
    "COM_OF_LOSS_T": 1.0,
    "COM_DISARM_PRFLT": 10.0, "COM_DISARM_LAND": 2.0, "NAV_ACC_RAD": 2.0, "MPC_XY_CRUISE": 5.0,
    "MPC_XY_VEL_MAX": 12.0, "MPC_Z_VEL_MAX_UP": 3.0, "MPC_Z_VEL_MAX_DN": 1.5, "MPC_ACC_HOR": 3.0,
    "COM_HOME_EN": 1.0,
    # geofence (src/modules/navigator/geofence_params.c): GF_ACTION 2 "Hold mode"; distances 0 = disabled
    "GF_ACTION": 2.0, "GF_MAX_HOR_DIST": 0.0, "GF_MAX_VER_DIST": 0.0,
}
#: PX4 parameters of type INT32: sent and accepted bytewise in PARAM_VALUE/PARAM_SET's float field
#: (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE); a PARAM_SET typed otherwise is refused without an answer
#: ("param types mismatch", src/modules/mavlink/mavlink_parameters.cpp)
PX4_INT_PARAMS = {"GF_ACTION", "MAV_SYS_ID", "COM_HOME_EN"}
#: parameters whose change alters the leg being flown (the firmware reads them every control cycle)
SPEED_PARAMS = {"WPNAV_SPEED", "WPNAV_SPEED_UP", "WPNAV_ACCEL", "MPC_XY_CRUISE", "MPC_XY_VEL_MAX",
                "MPC_Z_VEL_MAX_UP", "MPC_ACC_HOR"}
#: the airframe's own horizontal limit (m/s) when no parameter bounds it (ArduCopter GUIDED velocity targets)
AIRFRAME_MAX_SPEED = 20.0

# SYS_STATUS onboard_control_sensors_*: ArduPilot (GCS_Common.cpp update_sensor_status_flags) reports AHRS and
# PREARM_CHECK as present; PX4 (src/modules/mavlink/streams/SYS_STATUS.hpp) reports neither as present, and
# XY_POSITION_CONTROL's health is its position estimate (both as observed on the firmware).
AP_SENSORS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_3D_MAG
              | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE | M.MAV_SYS_STATUS_SENSOR_GPS | M.MAV_SYS_STATUS_AHRS
              | M.MAV_SYS_STATUS_PREARM_CHECK | M.MAV_SYS_STATUS_SENSOR_BATTERY
              | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL | M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL)
PX4_SENSORS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_3D_MAG
               | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE | M.MAV_SYS_STATUS_SENSOR_GPS
               | M.MAV_SYS_STATUS_SENSOR_BATTERY | M.MAV_SYS_STATUS_LOGGING
               | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL)

# EKF_STATUS_REPORT.flags (libraries/AP_NavEKF3/AP_NavEKF3_Outputs.cpp getFilterStatus -> send_status_report):
# before GPS is fused the EKF holds a constant position; "EKF3 IMU0 is using GPS" adds the horizontal position.
EKF_NO_POSITION = (M.EKF_ATTITUDE | M.EKF_VELOCITY_HORIZ | M.EKF_VELOCITY_VERT | M.EKF_POS_VERT_ABS
                   | M.EKF_CONST_POS_MODE)
EKF_POSITION = (M.EKF_ATTITUDE | M.EKF_VELOCITY_HORIZ | M.EKF_VELOCITY_VERT | M.EKF_POS_VERT_ABS
                | M.EKF_POS_HORIZ_REL | M.EKF_POS_HORIZ_ABS | M.EKF_PRED_POS_HORIZ_REL | M.EKF_PRED_POS_HORIZ_ABS)
EKF_STATUS_REPORT_ID = 193  # ardupilotmega.xml

#: ArduPilot repeats failing pre-arm checks as "PreArm: ..." every 30 s while disarmed (AP_Arming.cpp
#: PREARM_DISPLAY_PERIOD); a refused arm command reports them as "Arm: ..." (AP_Arming::arm -> check_failed)
AP_PREARM_DISPLAY_PERIOD_S = 30.0
#: PX4 resends MISSION_ITEM_REACHED of the last reached item 10 times, once a second
#: (src/modules/mavlink/mavlink_mission.cpp: _reached_sent_count)
PX4_REACHED_REPEATS = 10
#: PX4 corrects the home altitude for 120 s after take-off in steps over 1 m (src/modules/commander/
#: HomePosition.hpp kHomePositionCorrectionTimeWindow, kAltitudeDifferenceThreshold)
PX4_HOME_CORRECTION_WINDOW_S = 120.0
PX4_HOME_CORRECTION_STEP_M = 1.0
#: PX4 commander: disarmed and landed, home follows the vehicle once it is farther from it than twice the GPS eph
#: (HomePosition::hasMovedFromCurrentHomeLocation; SIH's simulated GPS reports eph 0.9 m)
PX4_HOME_MOVED_M = 1.8
