"""Three drones, one application, one clock (the SITL fleet test): each flies to two waypoints 5 m apart, hovers
3 s at each, and lands. Run: aerodaas run tests/sitl_fleet_app.py --env FLEET.json"""
from aerodaas import *

env = Environment("../apps/farm_survey.json")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)
for k, drone in enumerate(env.get_env_robots()):
    wps = [Waypoint(id=f"{drone.id}_wp{i + 1}", x=3.0 * k, y=y, z=1.5, hover_duration=3, waypoint_type="relative")
           for i, y in enumerate((3.0, 8.0))]
    drone.navigate(scheduler.generate_navigation(
        AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, SchedulingType.ORDERED)))
result = env.start_mission()
