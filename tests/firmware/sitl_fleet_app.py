"""Three drones, one application, one clock (the SITL fleet test): each flies to two waypoints 5 m apart, hovers
3 s at each, and lands, with the waypoints' acceptance radius the firmware can hold (``AERODAAS_SITL_HOLD_RADIUS_M``,
metres; default 0.3: see tests/firmware/sitl.py HOLD_RADIUS). Run: aerodaas run tests/firmware/sitl_fleet_app.py --env FLEET.json"""
import os

from aerodaas import *

radius = float(os.environ.get("AERODAAS_SITL_HOLD_RADIUS_M", "0.3"))
env = Environment("../apps/farm_survey.json")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)
for k, drone in enumerate(env.get_env_robots()):
    wps = [Waypoint(id=f"{drone.id}_wp{i + 1}", x=3.0 * k, y=y, z=1.5, hover_duration=3, waypoint_type="relative",
                    acceptance_radius=radius)
           for i, y in enumerate((3.0, 8.0))]
    drone.navigate(scheduler.generate_navigation(
        AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, SchedulingType.ORDERED)))
result = env.start_mission()
