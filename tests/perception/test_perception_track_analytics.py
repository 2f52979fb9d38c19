"""TrackAnalytics on frames of a simulated camera whose truth is known: two drones, each
watching three cars that drive through its view, detected with pixel noise, missed detections, low scores and an
occlusion. Counts id switches (a truth object whose track id changes) and the geo-location error."""
from __future__ import annotations

import numpy as np

from aerodaas.model.types import CameraIntrinsics, Detection, FrameMeta, FramePose, GeoPoint
from aerodaas.analytics.track import TrackAnalytics
from aerodaas.model.camera import project_points

K = CameraIntrinsics.from_hfov(640, 480, 78.0)
HOME = GeoPoint(lat=47.397742, lon=8.545594, alt=488.0)
DRONES = {"d1": (0.0, 0.0, 20.0), "d2": (80.0, 0.0, 20.0)}


def _cars(robot: str, t: float) -> dict[int, tuple[float, float]]:
    x0 = DRONES[robot][0]
    return {0: (x0 - 10 + 1.5 * t, -4.0), 1: (x0 + 10 - 1.2 * t, 0.0), 2: (x0 - 3.0, 5.0 - 0.8 * t)}


def test_stable_ids_and_geolocation_on_a_two_drone_run():
    rng = np.random.default_rng(7)
    tracks = TrackAnalytics(classes="car", home=HOME)
    owner: dict[tuple[str, int], int] = {}  # (robot, truth id) -> track id
    switches, errors, frames = 0, [], 0
    for k in range(100):
        t = 0.1 * k
        for robot, pos in DRONES.items():
            meta = FrameMeta(robot_id=robot, sensor_id="cam", seq=k, capture_time=t, wall_time=0.0,
                             pose=FramePose(position=pos, yaw=90.0, camera_pitch=90.0), intrinsics=K)
            dets, truth_of = [], {}
            for oid, xy in _cars(robot, t).items():
                if oid == 1 and 40 <= k < 46:
                    continue  # under a tree for 6 frames
                if rng.random() < 0.1:
                    continue  # a missed detection
                (u, v), = project_points(np.array([[xy[0], xy[1], 0.0]]), meta.pose, K)[0]
                u, v = u + rng.normal(0, 1.0), v + rng.normal(0, 1.0)
                score = 0.2 if rng.random() < 0.2 else 0.7  # some low-score frames (the BYTE step)
                truth_of[len(dets)] = (oid, xy)
                dets.append(Detection(class_id=2, class_name="car", score=score, box=(u - 12, v - 6, u + 12, v + 6)))
            out = tracks.process(dets, meta)
            frames += 1
            for row in out:
                j = next(i for i, d in enumerate(dets) if d.box == row["box"])
                oid, xy = truth_of[j]
                prev = owner.get((robot, oid))
                if prev is not None and prev != row["track_id"]:
                    switches += 1
                owner[(robot, oid)] = row["track_id"]
                errors.append(float(np.hypot(row["enu"][0] - xy[0], row["enu"][1] - xy[1])))
                assert row["robot"] == robot and row["sigma_m"] > 0 and "lat" in row
    assert len(owner) == 6  # every car of both drones got a track
    assert switches * 100 / frames <= 1.0  # id switches per 100 frames
    assert max(errors) <= 1.5  # metres, at 20 m altitude with 1 px noise
    assert tracks.stats()["tracks_by_drone"] == {"d1": 3, "d2": 3}
