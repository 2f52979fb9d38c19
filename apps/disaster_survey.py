"""Disaster-area survey (paper §6.1, pattern 2): 4 pre-planned waypoints over a 10 m x 10 m area at 1.5 m/s;
a remote user adds waypoints mid-mission through the human-in-the-loop API and the scheduler re-plans.
Run: aerodaas run apps/disaster_survey.py   then, from another shell:
     aerodaas inject --drone quadrotor_base --waypoint 5,20,2,2 --waypoint 0,15,2,2 --waypoint 10,15,2,2"""
from aerodaas import *

env = Environment("disaster_survey.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("quadrotor_base")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)

monitor = MonitoringAnalytics(["battery", "height", "speed"])
monitor.deploy(edge)
monitor.analyse(drone.get_sensor_by_id("odom").get_data_stream())

corners = [(0, 0), (10, 10), (0, 10), (10, 0)]
survey = AeroNavigation(NavigationType.DISTANCE_DRIVEN,
                        [Waypoint(id=f"wp{i + 1}", x=x, y=y, z=2, hover_duration=2) for i, (x, y) in enumerate(corners)],
                        SchedulingType.UNORDERED)
drone.navigate(scheduler.generate_navigation(survey))
result = drone.start_mission()
