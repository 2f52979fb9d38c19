"""Two drones flown as one fleet with ``env.start_mission([d1, d2])`` (a fleet's start is not
reported as "never called start_mission()"): each flies one waypoint 4 m from home and lands.
Run: aerodaas run tests/apps/fleet_two_drones.py --speedup 20"""
from aerodaas import *

env = Environment("fleet_two_drones.json")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)
d1, d2 = env.get_robot_by_id("d1"), env.get_robot_by_id("d2")
for k, drone in enumerate((d1, d2)):
    wp = Waypoint(id=f"{drone.id}_wp1", x=4.0, y=3.0 * k, z=2.0, hover_duration=1, waypoint_type="relative")
    drone.navigate(scheduler.generate_navigation(
        AeroNavigation(NavigationType.DISTANCE_DRIVEN, [wp], SchedulingType.ORDERED)))
result = env.start_mission([d1, d2])
