"""apps/farm_survey.py's survey for the SITL tests, with the waypoints' acceptance radius the firmware can hold
(``AERODAAS_SITL_HOLD_RADIUS_M``, metres; default 0.3 as the app: see tests/firmware/sitl.py HOLD_RADIUS) and
only its first ``AERODAAS_SITL_CORNERS`` corners (default all 4; a scenario that tests one leg's flight flies 2).
Run: aerodaas run tests/firmware/sitl_survey_app.py --env FARM.json"""
import os

from aerodaas import *

radius = float(os.environ.get("AERODAAS_SITL_HOLD_RADIUS_M", "0.3"))
corners = [(0, 0), (0, 10), (10, 10), (10, 0)][:int(os.environ.get("AERODAAS_SITL_CORNERS", "4"))]
env = Environment("../apps/farm_survey.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("quadrotor_base")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)
monitor = MonitoringAnalytics(["battery", "height", "gps"])
monitor.deploy(edge)
monitor.analyse(drone.get_sensor_by_id("odom").get_data_stream())
waypoints = [Waypoint(id=f"wp{i + 1}", x=x, y=y, z=1.5, hover_duration=5, waypoint_type="relative",
                      acceptance_radius=radius) for i, (x, y) in enumerate(corners)]
drone.navigate(scheduler.generate_navigation(
    AeroNavigation(NavigationType.DISTANCE_DRIVEN, waypoints, SchedulingType.UNORDERED)))
result = drone.start_mission()
