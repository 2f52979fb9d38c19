"""Geo-located tracks recorded in a run: two drones at 20 m, each over its own cars (moving and
parked, the simulator's targets). A colour "detector" finds the magenta cars in the rendered pixels (it does not
know the simulator's truth), one TrackAnalytics (ByteTrack per drone + geo-location) is shared by both drones; the
runtime records each drone's tracks under /<robot>/tracks/tracks (image annotations, /scene, /fixes).
Run: aerodaas run tests/apps/fleet_tracks.py --record tracks.mcap"""
import cv2
import numpy as np

from aerodaas import *


class MagentaCars(Analytics):
    """Every magenta blob of at least ``min_px`` pixels is a car, its box the blob's bounding box. Made as unreliable
    as a real detector, deterministically from the frame number and the blob: 10 % of the cars are missed, 20 % come
    with a low score (0.2, below ByteTrack's high threshold: only its second association keeps them), the rest 0.9."""

    name = "cars"
    stateful = False
    min_px = 40

    def process(self, frame, meta):
        f = frame.astype(np.int16)
        mask = ((f[..., 2] > 90) & (f[..., 0] > 90) & (f[..., 1] < 60)).astype(np.uint8)
        n, _, stats, _ = cv2.connectedComponentsWithStats(mask)
        out = []
        for x, y, w, h, area in stats[1:n]:
            k = (meta.seq * 7 + int(x) // 16 + int(y) // 16) % 10 if meta is not None else 5
            if area >= self.min_px and k != 0:  # k == 0: missed
                out.append(Detection(class_id=2, class_name="car", score=0.2 if k in (1, 2) else 0.9,
                                     box=(float(x), float(y), float(x + w), float(y + h))))
        return out


env = Environment("fleet_tracks.json")
edge = env.get_compute_resource_by_id("edge")
scheduler = NearestNeighborScheduler(env)
env.set_trajectory_scheduler(scheduler)
detector, tracks = MagentaCars(), TrackAnalytics(classes="car", tracker=ByteTrackConfig(track_buffer=10))
detector.deploy(edge)
tracks.deploy(edge)
drones = [env.get_robot_by_id("d1"), env.get_robot_by_id("d2")]
for drone in drones:
    detector.analyse(drone.get_sensor_by_id("cam").get_data_stream())  # one detector, one tracker, both drones
tracks.analyse(detector.output)
for drone, side in zip(drones, (-1.0, 1.0)):
    hover = [Waypoint(id=f"{drone.id}_over_cars", x=15.0 * side, y=0.0, z=20.0, hover_duration=25.0),
             Waypoint(id=f"{drone.id}_home", x=0.0, y=0.0, z=20.0)]
    drone.navigate(scheduler.generate_navigation(
        PriorityQueue(AeroNavigation(NavigationType.DISTANCE_DRIVEN, hover, SchedulingType.ORDERED), priority=2)))
result = env.start_mission(drones)
