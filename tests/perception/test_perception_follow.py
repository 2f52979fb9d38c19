"""FollowAnalytics following a ByteTrack track id: a second car that comes near while the
target is hidden does not steal the follow, and the target is re-acquired under its id when it reappears."""
from __future__ import annotations

import numpy as np

from aerodaas import FollowAnalytics
from aerodaas.model.types import CameraIntrinsics, Detection, FrameMeta, FramePose
from aerodaas.perception.tracking import ByteTrackConfig
from aerodaas.model.camera import project_points

K = CameraIntrinsics.from_hfov(640, 480, 78.0)
DRONE = (0.0, 0.0, 20.0)


def _meta(seq: int, t: float) -> FrameMeta:
    return FrameMeta(robot_id="d1", sensor_id="cam", seq=seq, capture_time=t, wall_time=0.0,
                     pose=FramePose(position=DRONE, yaw=90.0, camera_pitch=90.0), intrinsics=K)


def _det(meta: FrameMeta, xy, score=0.9, half_px=10.0) -> Detection:
    uv, _ = project_points(np.array([[xy[0], xy[1], 0.0]]), meta.pose, meta.intrinsics)
    u, v = uv[0]
    return Detection(class_id=2, class_name="car", score=score,
                     box=(u - half_px, v - half_px, u + half_px, v + half_px))


def _run(follow: FollowAnalytics) -> list[np.ndarray | None]:
    """Car A drives +x at 1 m/s; frames 10-15 it is hidden (under a tree) while parked car B, 2.5 m from A's
    predicted path, is in view; from frame 16 both are seen. Returns the follow's track position per frame."""
    out = []
    for k in range(30):
        t = 0.1 * k
        m = _meta(k, t)
        a = (-3.0 + 1.0 * t, 0.0)
        dets = []
        if not 10 <= k < 16:
            dets.append(_det(m, a))
        if k >= 10:
            dets.append(_det(m, (-1.5, 2.5), score=0.95))
        follow.generate_navigation(dets, m)
        st = follow.track_of("d1")
        out.append(None if st.track is None else st.track.copy())
    return out


def test_follow_keeps_its_track_id_through_an_occlusion():
    tracked = FollowAnalytics(target_classes=["car"], confirm_hits=2, gate_m=4.0, lost_after=2.0,
                              tracker=ByteTrackConfig(track_buffer=10))
    pos = _run(tracked)
    st = tracked.track_of("d1")
    assert st.target_id == 1
    a_end = np.array([-3.0 + 2.9, 0.0])
    assert np.linalg.norm(pos[-1] - a_end) < 0.5  # on car A
    assert all(np.linalg.norm(p - np.array([-1.5, 2.5])) > 1.0 for p in pos if p is not None)  # never on B


def test_without_a_tracker_the_nearest_box_steals_the_follow():
    """The previous behaviour, kept as the default: the gated nearest detection of each frame."""
    plain = FollowAnalytics(target_classes=["car"], confirm_hits=2, gate_m=4.0, lost_after=2.0)
    pos = _run(plain)
    assert any(p is not None and np.linalg.norm(p - np.array([-1.5, 2.5])) < 0.5 for p in pos)
