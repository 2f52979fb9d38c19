"""Surveillance and vehicle tracking (paper §6.4, pattern 4): a low-priority survey; when the detector finds
the car, a priority-1 follow mission preempts it; when the car leaves the view the survey resumes.
Runs on a fresh clone: the aerial model, the ground photo and the car ship in the package
(``package:`` images in vehicle_tracking.json, aerodaas/sim/ground)"""
from aerodaas import *

env = Environment("vehicle_tracking.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("quadrotor_base")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)
frames = drone.get_sensor_by_id("cam1").get_data_stream()

survey = AeroListData([Waypoint(id=f"wp{i + 1}", x=x, y=-4, z=16, hover_duration=2) for i, x in enumerate((-20, 0, 20))])
drone_nav = scheduler.generate_navigation(PriorityQueue(survey, priority=2))

vehicles = ["car", "large_vehicle"]
# the shipped aerial model (MODEL_CARD.md), never enlarging a frame (a 640x480 camera's go in at 480x640, a 1080p
# one's at the model's 736x1280); one NMS over its vehicle classes (a car is not also a large vehicle). The COCO
# one stays by name: "yolox_nano", ["car", "truck", "bus"]
detector = ObjectDetector("aerial_nano", classes=vehicles, score_threshold=0.3, upscale=False,
                          class_groups={"vehicle": vehicles})
detector.deploy(edge)
# follows one ByteTrack track id, and only one that moves (>= 0.5 m/s): the aerial model also sees parked cars
track_cfg = ByteTrackConfig(high_threshold=0.3, new_track_threshold=0.3)  # the detector's threshold
follow = FollowAnalytics(target_classes=vehicles, tracker=track_cfg, moving=MovingTarget())
follow.deploy(edge, colocate=True)  # cheap and per drone: runs inside the drone actor, no hop
car_nav = follow.analyse(detector.analyse(frames))
scheduler.add_navigation(PriorityQueue(car_nav, priority=1))

drone.navigate(drone_nav)
result = drone.start_mission()
