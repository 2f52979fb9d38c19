"""One drone flying an ORDERED list of waypoints given in ``AERODAAS_SITL_WAYPOINTS`` (``"id:x:y:hover;..."``, ENU
metres from home and seconds of hover, at 2 m), with the acceptance radius of ``AERODAAS_SITL_HOLD_RADIUS_M`` (default
0.3 m): the overlapping-fence scenarios of tests/firmware/test_sitl_fence.py. Run: aerodaas run tests/firmware/sitl_overlap_app.py --env
ENV.json"""
import os

from aerodaas import *

radius = float(os.environ.get("AERODAAS_SITL_HOLD_RADIUS_M", "0.3"))
env = Environment("../apps/farm_survey.json")
drone = env.get_robot_by_id("quadrotor_base")
waypoints = []
for spec in os.environ["AERODAAS_SITL_WAYPOINTS"].split(";"):
    wid, x, y, hover = spec.split(":")
    waypoints.append(Waypoint(id=wid, x=float(x), y=float(y), z=2.0, hover_duration=float(hover),
                              waypoint_type="relative", acceptance_radius=radius))
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, waypoints, SchedulingType.ORDERED))
result = drone.start_mission()
