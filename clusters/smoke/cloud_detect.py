"""Smoke-test application for a real edge + cloud cluster (clusters/smoke/ray_up_test.sh): one drone hovers 40 s
over the embedded simulator's procedural ground while a YOLOX-Nano detector, deployed on CLOUD compute, analyses
its camera. With cloud_detect.json the detector runs in the cloud host on a tier=cloud node; with
cloud_detect_dems.json the DEMS analytics scheduler places every frame's detection (its QoS there makes the edge too
slow for the deadline, so DEMS sends every task to the cloud while one is reachable, and drops them, with the
reason, once the cloud is lost).
The model needs to be only where this driver runs ($AERODAAS_MODEL_DIR, the cache, or a download): the driver ships
it to the nodes that run the detector.

Run (on the head of a cluster): aerodaas run clusters/smoke/cloud_detect.py --address auto"""
from aerodaas import *

env = Environment("cloud_detect.json")
cloud = env.get_compute_resource_by_id("cloud")
drone = env.get_robot_by_id("uav")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)

detector = ObjectDetector("yolox_nano", score_threshold=0.3)
detector.deploy(cloud)
detector.analyse(drone.get_sensor_by_id("cam").get_data_stream())

hover = AeroListData([Waypoint(id="hover", x=0.0, y=0.0, z=14.0, hover_duration=40)])
drone.navigate(scheduler.generate_navigation(PriorityQueue(hover, priority=2)))
result = drone.start_mission()
