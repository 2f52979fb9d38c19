"""The simulated world seen by the camera: a textured ground plane (z = 0) and moving targets.

The camera is a pinhole (OpenCV convention: x right, y down, z forward) mounted on the drone, pitched
``pitch_deg`` below the horizon (90 = nadir) and yawed with the drone. Because the ground is a plane, the
ground-texture -> image mapping is a homography ``H = K [r1 r2 t] M`` (Hartley & Zisserman, *Multiple View
Geometry*, §8.1.1 "plane-induced homography"), rendered with ``cv2.warpPerspective``; targets are image crops
laid on the ground as rectangles of their real size and warped the same way.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from aerodaas.config import GroundConfig, TargetConfig
from aerodaas.model.camera import ground_to_image_homography, pixel_to_ground, project_points
from aerodaas.model.types import CameraIntrinsics, FramePose
from aerodaas.sim import ground_cache

SKY_BGR = (235, 206, 135)


def procedural_ground(cfg: GroundConfig) -> tuple[np.ndarray, float, tuple[float, float]]:
    """A farm-like ground texture (fields with crop rows, tracks, noise) generated from ``cfg.seed``.

    Returns ((H, W, 3) uint8 BGR texture, metres per pixel, home pixel (x, y))."""
    mpp = cfg.metres_per_pixel
    n = int(round(cfg.size_m / mpp))
    rng = np.random.default_rng(cfg.seed)
    base = np.zeros((n, n, 3), np.float32)
    # fields: a coarse grid of patches with different crop colours
    palette = np.array([[60, 140, 70], [50, 120, 90], [70, 160, 120], [40, 100, 110], [80, 150, 150]], np.float32)
    cells = rng.integers(0, len(palette), (6, 6))
    patch = palette[cells]
    base[:] = cv2.resize(patch, (n, n), interpolation=cv2.INTER_NEAREST)
    # crop rows every ~0.75 m, orientation per field
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32)
    rows_h = (np.sin(2 * np.pi * yy * mpp / 0.75) > 0.6).astype(np.float32)
    rows_v = (np.sin(2 * np.pi * xx * mpp / 0.75) > 0.6).astype(np.float32)
    orient = cv2.resize((rng.random((6, 6)) > 0.5).astype(np.float32), (n, n), interpolation=cv2.INTER_NEAREST)
    rows = np.where(orient > 0.5, rows_h, rows_v)
    base *= (1.0 - 0.25 * rows)[..., None]
    # multi-octave noise
    noise = np.zeros((n, n), np.float32)
    for octave, amp in ((8, 18.0), (32, 10.0), (128, 6.0)):
        small = rng.normal(0, 1, (octave, octave)).astype(np.float32)
        noise += amp * cv2.resize(small, (n, n), interpolation=cv2.INTER_CUBIC)
    base += noise[..., None]
    # farm tracks (dirt roads) between fields
    step = n // 6
    for i in range(1, 6):
        cv2.line(base, (0, i * step), (n, i * step), (90, 130, 160), max(2, int(2.5 / mpp)))
        cv2.line(base, (i * step, 0), (i * step, n), (90, 130, 160), max(2, int(2.5 / mpp)))
    tex = np.clip(base, 0, 255).astype(np.uint8)
    return tex, mpp, (n / 2.0, n / 2.0)


def ground_pyramid(ground: GroundConfig) -> list[tuple[np.ndarray, float, tuple[float, float]]]:
    """The ground texture (``ground.image`` or :func:`procedural_ground`) and its mip pyramid (``cv2.pyrDown``
    until the smaller side is at most 256 px, at most 6 levels), used to avoid aliasing when the camera sees the
    ground at a coarser sampling than the texture.

    Returns [((H, W, 3) uint8 BGR, metres per pixel, home pixel (x, y))], finest first. Raises ValueError when
    the image cannot be decoded."""
    if ground.image:
        tex = cv2.imread(ground.image, cv2.IMREAD_COLOR)
        if tex is None:
            raise ValueError(f"world.ground.image: cannot decode image {ground.image!r}")
        mpp = ground.metres_per_pixel
        home = ground.home_px or (tex.shape[1] / 2.0, tex.shape[0] / 2.0)
    else:
        tex, mpp, home = procedural_ground(ground)
    # mip pyramid to avoid aliasing when the camera sees the ground at a coarser sampling than the texture
    levels = [(tex, mpp, home)]
    while min(levels[-1][0].shape[:2]) > 256 and len(levels) < 6:
        t, m, h = levels[-1]
        levels.append((cv2.pyrDown(t), m * 2.0, (h[0] / 2.0, h[1] / 2.0)))
    return levels


@dataclass
class _Target:
    cfg: TargetConfig
    image: np.ndarray  # (h, w, 3) BGR crop
    times: np.ndarray
    xy: np.ndarray


#: Height of the camera above the ground when the drone is landed (metres); a camera in the ground plane
#: would make the ground homography singular.
CAMERA_MIN_HEIGHT_M = 0.05


class World:
    """Ground texture + moving targets; renders camera frames and reports target ground truth."""

    def __init__(self, ground: GroundConfig, targets: list[TargetConfig]) -> None:
        if ground_cache.enabled():  # one read-only copy per machine, shared by every rendering process
            key = ground_cache.ground_key(ground.model_dump_json(), ground.image)
            self.levels = ground_cache.shared_levels(key, lambda: ground_pyramid(ground))
        else:
            self.levels = ground_pyramid(ground)
        self.targets: list[_Target] = []
        for t in targets:
            img = cv2.imread(t.image, cv2.IMREAD_COLOR)
            if img is None:
                raise ValueError(f"world.targets[{t.id}].image: cannot decode image {t.image!r}")
            x0, y0, x1, y1 = t.crop
            if x1 > img.shape[1] or y1 > img.shape[0]:
                raise ValueError(f"world.targets[{t.id}].crop {t.crop} lies outside the image of size "
                                 f"{img.shape[1]}x{img.shape[0]}")
            self.targets.append(_Target(t, np.ascontiguousarray(img[y0:y1, x0:x1]),
                                        np.array([p.t for p in t.path]), np.array([[p.x, p.y] for p in t.path])))

    # ------------------------------------------------------------------ targets
    def target_states(self, t: float) -> list[dict]:
        """Ground truth at sim time ``t``: id, class, ENU x/y (m), heading (deg), present flag."""
        out = []
        for tg in self.targets:
            present = tg.times[0] <= t <= tg.times[-1]
            i = int(np.clip(np.searchsorted(tg.times, t) - 1, 0, len(tg.times) - 2))
            t0, t1 = tg.times[i], tg.times[i + 1]
            a = float(np.clip((t - t0) / (t1 - t0), 0.0, 1.0))
            p = (1 - a) * tg.xy[i] + a * tg.xy[i + 1]
            d = tg.xy[i + 1] - tg.xy[i]
            heading = math.degrees(math.atan2(d[1], d[0])) if np.hypot(*d) > 1e-9 else 0.0
            vel = d / (t1 - t0) if present else np.zeros(2)
            out.append({"id": tg.cfg.id, "class_name": tg.cfg.class_name, "x": float(p[0]), "y": float(p[1]),
                        "heading": heading, "vx": float(vel[0]), "vy": float(vel[1]), "present": bool(present)})
        return out

    def _target_corners(self, tg: _Target, st: dict) -> np.ndarray:
        L = tg.cfg.length_m
        W = L * tg.image.shape[0] / tg.image.shape[1]
        h = math.radians(st["heading"])
        fwd = np.array([math.cos(h), math.sin(h)])
        left = np.array([-math.sin(h), math.cos(h)])
        c = np.array([st["x"], st["y"]])
        # crop corners: top-left, top-right, bottom-right, bottom-left; crop right edge = front, top = left side
        pts = [c - fwd * L / 2 + left * W / 2, c + fwd * L / 2 + left * W / 2,
               c + fwd * L / 2 - left * W / 2, c - fwd * L / 2 - left * W / 2]
        return np.array([[p[0], p[1], 0.0] for p in pts])

    # ------------------------------------------------------------------ rendering
    def render(self, pose: FramePose, k: CameraIntrinsics, t: float,
               out: np.ndarray | None = None) -> tuple[np.ndarray, list[dict]]:
        """Render what the camera sees at sim time ``t``, into ``out`` when given (a writable (k.height, k.width, 3)
        uint8 array, e.g. a same-node channel's shared-memory slot: the frame is then made where it travels from).

        Returns ((k.height, k.width, 3) uint8 BGR frame (``out`` itself when given), ground truth per target with ``in_view`` (any corner
        visible), ``fully_in_view`` (all four corners inside the image) and ``bbox_px`` (x0, y0, x1, y1))."""
        if pose.position[2] < CAMERA_MIN_HEIGHT_M:  # on the ground: the lens sits above it, never in the plane
            pose = pose.model_copy(update={"position": (pose.position[0], pose.position[1], CAMERA_MIN_HEIGHT_M)})
        Hg = ground_to_image_homography(pose, k)
        # pick the pyramid level whose texel is closest to (but finer than) the ground sample distance
        alt = max(pose.position[2], 0.1)
        gsd = alt / k.fx / max(math.sin(math.radians(pose.camera_pitch)), 0.2)
        lvl = 0
        for i, (_, m, _) in enumerate(self.levels):
            if m <= gsd * 1.2:
                lvl = i
        tex, mpp, (hx, hy) = self.levels[lvl]
        M = np.array([[mpp, 0, -hx * mpp], [0, -mpp, hy * mpp], [0, 0, 1.0]])
        H = Hg @ M
        frame = cv2.warpPerspective(tex, H, (k.width, k.height), dst=out, flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_REFLECT_101)
        if pose.camera_pitch < 90.0:
            self._paint_sky(frame, pose, k)
        truth = []
        for tg, st in zip(self.targets, self.target_states(t)):
            info = dict(st, in_view=False, fully_in_view=False, bbox_px=None)
            if st["present"]:
                corners = self._target_corners(tg, st)
                uv, front = project_points(corners, pose, k)
                if front.all():
                    inside = (uv[:, 0] >= 0) & (uv[:, 0] < k.width) & (uv[:, 1] >= 0) & (uv[:, 1] < k.height)
                    x0, y0 = uv.min(0)
                    x1, y1 = uv.max(0)
                    vis = x1 >= 0 and y1 >= 0 and x0 < k.width and y0 < k.height
                    if vis:
                        self._draw_target(frame, tg.image, uv)
                        info.update(in_view=True, fully_in_view=bool(inside.all()),
                                    bbox_px=[float(max(x0, 0)), float(max(y0, 0)), float(min(x1, k.width)), float(min(y1, k.height))])
            truth.append(info)
        return frame, truth

    @staticmethod
    def _draw_target(frame: np.ndarray, crop: np.ndarray, uv: np.ndarray) -> None:
        h, w = crop.shape[:2]
        src = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
        x0, y0 = np.floor(uv.min(0)).astype(int)
        x1, y1 = np.ceil(uv.max(0)).astype(int)
        x0, y0 = max(x0, 0), max(y0, 0)
        x1, y1 = min(x1, frame.shape[1]), min(y1, frame.shape[0])
        if x1 <= x0 or y1 <= y0:
            return
        dst = np.float32(uv - [x0, y0])
        P = cv2.getPerspectiveTransform(src, dst)
        size = (x1 - x0, y1 - y0)
        warped = cv2.warpPerspective(crop, P, size, flags=cv2.INTER_LINEAR)
        mask = cv2.warpPerspective(np.full((h, w), 255, np.uint8), P, size, flags=cv2.INTER_LINEAR)
        roi = frame[y0:y1, x0:x1]
        a = (mask.astype(np.float32) / 255.0)[..., None]
        roi[:] = (warped * a + roi * (1.0 - a)).astype(np.uint8)

    @staticmethod
    def _paint_sky(frame: np.ndarray, pose: FramePose, k: CameraIntrinsics) -> None:
        # rows whose centre ray does not hit the ground are sky (camera has no roll, so the horizon is a row)
        for v in range(k.height):
            if pixel_to_ground(k.cx, v, pose, k) is not None:
                if v:
                    frame[:v] = SKY_BGR
                return
        frame[:] = SKY_BGR
