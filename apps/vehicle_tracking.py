"""Surveillance and vehicle tracking (paper §6.4, pattern 4): a low-priority survey; when the detector finds
the car, a priority-1 follow mission preempts it; when the car leaves the view the survey resumes.
Needs real imagery and the YOLOX-Nano model: AERODAAS_DATA_DIR=../shared/data AERODAAS_MODEL_DIR=../shared/data/models"""
from aerodaas import *

env = Environment("vehicle_tracking.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("quadrotor_base")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)
frames = drone.get_sensor_by_id("cam1").get_data_stream()

survey = AeroListData([Waypoint(id=f"wp{i + 1}", x=x, y=-4, z=16, hover_duration=2) for i, x in enumerate((-20, 0, 20))])
drone_nav = scheduler.generate_navigation(PriorityQueue(survey, priority=2))

vehicles = ["car", "truck", "bus"]
# one NMS over the vehicle classes: a car is not also reported as a truck (two tracks on one vehicle)
detector = ObjectDetector("yolox_nano", classes=vehicles, score_threshold=0.15, class_groups={"vehicle": vehicles})
detector.deploy(edge)
# follows one ByteTrack track id; its geo-located tracks are recorded (/quadrotor_base/follow/tracks)
track_cfg = ByteTrackConfig(high_threshold=0.15, new_track_threshold=0.15)  # the detector's threshold
follow = FollowAnalytics(target_classes=vehicles, tracker=track_cfg)
follow.deploy(edge, colocate=True)  # cheap and per drone: runs inside the drone actor, no hop
car_nav = follow.analyse(detector.analyse(frames))
scheduler.add_navigation(PriorityQueue(car_nav, priority=1))

drone.navigate(drone_nav)
result = drone.start_mission()
