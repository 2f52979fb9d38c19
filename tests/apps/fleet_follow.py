"""Two drones share one FollowAnalytics (a shared follow kept one track and mixed the drones' targets).
Each drone surveys towards its own parked car (d1 west, d2 east); a ground-truth "detector" reports every car in a
frame's field of view (cars are visible until t = 14 s, then gone); the shared follow preempts each survey and puts
each drone over its own car; when the cars are gone the surveys resume and both drones land at home.
Run: aerodaas run tests/apps/fleet_follow.py --record follow.mcap"""
import numpy as np

from aerodaas import *
from aerodaas.model.camera import project_points

CARS = {"car_west": (-12.0, 0.0), "car_east": (12.0, 0.0)}  # ENU metres from the (shared) home
GONE_AT = 14.0  # s: the cars leave the scene


class GroundTruthCars(Analytics):
    """Reports each car whose ground position projects into the frame (a perfect detector, 8 px boxes)."""

    name = "cars"
    stateful = False

    def process(self, frame, meta):
        if meta.capture_time >= GONE_AT:
            return []
        pts = np.array([[x, y, 0.0] for x, y in CARS.values()])
        uv, front = project_points(pts, meta.pose, meta.intrinsics)
        k = meta.intrinsics
        return [Detection(class_id=2, class_name="car", score=0.9, box=(u - 4, v - 4, u + 4, v + 4))
                for (u, v), f in zip(uv, front) if f and 0 <= u < k.width and 0 <= v < k.height]


env = Environment("fleet_follow.json")
edge = env.get_compute_resource_by_id("edge")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)
detector, follow = GroundTruthCars(), FollowAnalytics(target_classes=["car"], max_speed=3.0)
detector.deploy(edge)
follow.deploy(edge)
drones = [env.get_robot_by_id("d1"), env.get_robot_by_id("d2")]
for drone in drones:
    detector.analyse(drone.get_sensor_by_id("cam").get_data_stream())  # one detector, one follow, for both drones
scheduler.add_navigation(PriorityQueue(follow.analyse(detector.output), priority=1))
for drone, side in zip(drones, (-1.0, 1.0)):
    survey = [Waypoint(id=f"{drone.id}_out", x=10.0 * side, y=2.0, z=6.0),
              Waypoint(id=f"{drone.id}_home", x=0.0, y=0.0, z=6.0)]
    drone.navigate(scheduler.generate_navigation(
        PriorityQueue(AeroNavigation(NavigationType.DISTANCE_DRIVEN, survey, SchedulingType.ORDERED), priority=2)))
result = env.start_mission(drones)
