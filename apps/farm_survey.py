"""Farm survey (paper §6.2, pattern 1): a pre-planned 10 m x 10 m survey at 1.5 m, hovering 5 s at each of
4 waypoints, with odometry monitored. Run: aerodaas run apps/farm_survey.py --record farm.mcap"""
from aerodaas import *

env = Environment("farm_survey.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("quadrotor_base")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)

odometry = drone.get_sensor_by_id("odom")
monitor = MonitoringAnalytics(["battery", "height", "gps"])
monitor.deploy(edge)
monitor.analyse(odometry.get_data_stream())

corners = [(0, 0), (0, 10), (10, 10), (10, 0)]
waypoints = [Waypoint(id=f"wp{i + 1}", x=x, y=y, z=1.5, hover_duration=5, waypoint_type="relative")
             for i, (x, y) in enumerate(corners)]
survey = AeroNavigation(NavigationType.DISTANCE_DRIVEN, waypoints, SchedulingType.UNORDERED)
drone.navigate(scheduler.generate_navigation(survey))
result = drone.start_mission()
