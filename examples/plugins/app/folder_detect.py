"""Car detection on a folder of photos (docs/extending-vehicles.md): the drone's camera takes its
frames from the ``image_folder`` frame source (examples/plugins/aerodaas_example_plugins/image_folder.py, installed
through the package's entry points), images with the capture times of the folder's index.csv, and the unchanged
built-in ObjectDetector finds the cars in them while the drone hovers; the recording holds each image at its
index time and the detections of it.
Needs the YOLOX-Nano model (AERODAAS_MODEL_DIR) and the folder: python make_frames.py frames (AERODAAS_DATA_DIR).
Run: aerodaas run examples/plugins/app/folder_detect.py --record folder.mcap"""
from aerodaas import *

env = Environment("folder_detect.json")
edge = env.get_compute_resource_by_id("edge")
drone = env.get_robot_by_id("uav")

detector = ObjectDetector("yolox_nano", classes=["car", "truck", "bus"], score_threshold=0.15)
detector.deploy(edge)
detector.analyse(drone.get_sensor_by_id("cam").get_data_stream())

# hover above home while the folder's images (3 s to 7.5 s of vehicle time) come in
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="hold", x=0, y=0, z=10, hover_duration=10)],
                              SchedulingType.ORDERED))
result = drone.start_mission()
