"""Search and rescue (paper §6.5, pattern 5): a lawnmower search; when a person is detected the search is
aborted (the queue is cleared, it never resumes) and replaced by following the person.
Needs real imagery and YOLOX-Nano (AERODAAS_DATA_DIR, AERODAAS_MODEL_DIR)."""
from aerodaas import *

env = Environment("search_and_rescue.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("quadrotor_base")
scheduler = TrajectoryScheduler(env)
frames = drone.get_sensor_by_id("cam1").get_data_stream()

lanes = [(-4, 4), (-14, 4), (-14, -12), (14, -12), (14, 4)]
search = AeroNavigation(NavigationType.DISTANCE_DRIVEN,
                        [Waypoint(id=f"wp{i + 1}", x=x, y=y, z=8) for i, (x, y) in enumerate(lanes)],
                        SchedulingType.ORDERED, name="search")
drone.navigate(scheduler.generate_navigation(search))

# persons in colour from the air: the COCO model by 640 px slices (a 1080p camera: 8 slices + the whole frame; the
# simulated 640x480 one: one slice, the frame itself). Real oblique footage: recall 0.10 whole, 0.44 sliced
# (docs/perception.md, "Persons in colour"); the aerial model learnt persons from thermal frames only
detector = ObjectDetector("yolox_nano", classes=["person"], score_threshold=0.12, tiling=Tiling(tile=640))
detector.deploy(edge)
follow = FollowAnalytics(target_classes=["person"], max_speed=2.0, gate_m=3.0, confirm_hits=4)
follow.deploy(edge)
rescue = follow.analyse(detector.analyse(frames))
scheduler.add_navigation(PriorityQueue(rescue, priority=1, replace=True))  # abort the search on first sight

result = drone.start_mission()
