"""Situation awareness for a VIP (paper §6.3, pattern 3): no waypoints at start; the detector finds the person
and the follow analytics keeps the drone ~2 m behind them. In parallel an emergency-pose analytics watches the
same frames for a fall and commands a landing (needs: pip install "aerodaas[fall]"; without it the app runs
without that check and says so). Needs real imagery and YOLOX-Nano (AERODAAS_DATA_DIR, AERODAAS_MODEL_DIR)."""
from aerodaas import *
from aerodaas.analytics.extra import FallDetector

env = Environment("situation_awareness.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("quadrotor_base")
scheduler = TrajectoryScheduler(env)
frames = drone.get_sensor_by_id("cam1").get_data_stream()

# persons in colour from the air: the COCO model by 640 px slices (a 1080p camera: 8 slices + the whole frame; the
# simulated 640x480 one: one slice, the frame itself). Real oblique footage: recall 0.10 whole, 0.44 sliced
# (docs/perception.md, "Persons in colour"); the aerial model learnt persons from thermal frames only
detector = ObjectDetector("yolox_nano", classes=["person"], score_threshold=0.12, tiling=Tiling(tile=640))
detector.deploy(edge)
follow = FollowAnalytics(target_classes=["person"], standoff_m=2.0, max_speed=2.0, gate_m=3.0)
follow.deploy(edge)
scheduler.add_navigation(PriorityQueue(follow.analyse(detector.analyse(frames)), priority=1))

ok, why = FallDetector.available()
if ok:
    emergency = FallDetector(every_n=5)
    emergency.deploy(edge)
    scheduler.add_navigation(PriorityQueue(emergency.analyse(frames), priority=0))
else:
    print(f"situation_awareness: emergency-pose check disabled: {why}")

result = drone.start_mission()
