"""The pinhole camera of a drone (OpenCV convention: x right, y down, z forward), pitched ``camera_pitch`` degrees
below the horizon (90 = nadir) and yawed with the drone, over a ground plane: the world (ENU) -> camera rotation, the
intrinsics matrix K, the plane-induced homography ``H = K [r1 r2 t]`` (Hartley & Zisserman, *Multiple View
Geometry*, §8.1.1), projection of ENU points to pixels and back-projection of a pixel to the ground. The simulator
renders with it (:mod:`aerodaas.sim.world`); analytics and geo-location invert it (:mod:`aerodaas.perception.geolocate`).
Units: metres (ENU), degrees, pixels.
"""
from __future__ import annotations

import math

import numpy as np

from aerodaas.model.types import CameraIntrinsics, FramePose

__all__ = ["camera_rotation", "intrinsics_matrix", "ground_to_image_homography", "project_points", "pixel_to_ground"]


def camera_rotation(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """World(ENU)->camera rotation, rows = camera x (right), y (down), z (optical axis) in ENU. Shape (3, 3)."""
    psi, th = math.radians(yaw_deg), math.radians(pitch_deg)
    f = np.array([math.cos(psi), math.sin(psi), 0.0])
    r = np.array([math.sin(psi), -math.cos(psi), 0.0])
    u = np.array([0.0, 0.0, 1.0])
    zc = math.cos(th) * f - math.sin(th) * u
    yc = np.cross(zc, r)
    return np.stack([r, yc, zc])


def intrinsics_matrix(k: CameraIntrinsics) -> np.ndarray:
    return np.array([[k.fx, 0, k.cx], [0, k.fy, k.cy], [0, 0, 1.0]])


def ground_to_image_homography(pose: FramePose, k: CameraIntrinsics) -> np.ndarray:
    """(3, 3) homography mapping ground ENU (x, y, 1) metres to image pixels (u, v, 1)."""
    R = camera_rotation(pose.yaw, pose.camera_pitch)
    C = np.asarray(pose.position, float)
    t = -R @ C
    return intrinsics_matrix(k) @ np.column_stack([R[:, 0], R[:, 1], t])


def project_points(pts_enu: np.ndarray, pose: FramePose, k: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Project (N, 3) ENU points; returns (N, 2) pixels and (N,) bool 'in front of the camera'."""
    R = camera_rotation(pose.yaw, pose.camera_pitch)
    pc = (np.asarray(pts_enu, float) - np.asarray(pose.position, float)) @ R.T
    front = pc[:, 2] > 1e-3
    z = np.where(front, pc[:, 2], 1.0)
    uv = np.stack([k.fx * pc[:, 0] / z + k.cx, k.fy * pc[:, 1] / z + k.cy], axis=1)
    return uv, front


def pixel_to_ground(u: float, v: float, pose: FramePose, k: CameraIntrinsics, ground_z: float = 0.0) -> tuple[float, float] | None:
    """Intersect the ray through pixel (u, v) with the plane z = ground_z; ENU (x, y) metres, or None above horizon."""
    R = camera_rotation(pose.yaw, pose.camera_pitch)
    d_cam = np.array([(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0])
    d = R.T @ d_cam
    C = np.asarray(pose.position, float)
    if d[2] >= -1e-9:
        return None
    s = (ground_z - C[2]) / d[2]
    p = C + s * d
    return (float(p[0]), float(p[1]))
