"""Footage for the labelling tests: small videos written with PyAV and recordings written with the project's own
MCAP writer on the channels a run records (``/<robot>/camera/<sensor>``, ``/<robot>/odometry``,
``/<robot>/pose``)."""
from __future__ import annotations

from pathlib import Path

import av
import cv2
import numpy as np

from aerodaas.recording.writer import McapRecorder

SIZE = (480, 640)  # H, W


def scene(k: int, size: tuple[int, int] = SIZE) -> np.ndarray:
    """A distinct ``(H, W, 3) uint8 BGR`` picture for each ``k``: blocks of random colours (seeded by ``k``),
    smooth enough to survive video compression, different enough that two ``k`` never look alike."""
    rng = np.random.default_rng(1000 + k)
    blocks = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
    return cv2.resize(blocks, (size[1], size[0]), interpolation=cv2.INTER_NEAREST)


def write_video(path: Path, scenes: list[int], fps: int = 4) -> Path:
    """An H.264 (or MPEG-4) video of one frame per entry of ``scenes`` (:func:`scene` of that number) at ``fps``."""
    with av.open(str(path), "w") as box:
        try:
            stream = box.add_stream("libx264", rate=fps)
        except (av.error.FFmpegError, ValueError):  # an FFmpeg without x264
            stream = box.add_stream("mpeg4", rate=fps)
        stream.width, stream.height, stream.pix_fmt = SIZE[1], SIZE[0], "yuv420p"
        for k in scenes:
            for packet in stream.encode(av.VideoFrame.from_ndarray(scene(k), format="bgr24")):
                box.mux(packet)
        for packet in stream.encode():
            box.mux(packet)
    return path


def write_recording(path: Path, images: list[np.ndarray], period_s: float = 1.0, robot: str = "drone1",
                    sensor: str = "cam0", odometry: bool = True) -> Path:
    """An MCAP recording as ``aerodaas run --record`` writes it (the recorder actor's calls): a camera frame every
    ``period_s`` on ``/<robot>/camera/<sensor>`` and, with ``odometry``, the vehicle's odometry (JSON) and pose
    (``foxglove.PoseInFrame``) five times a second, the vehicle at x = 10 m per second of flight."""
    t0 = 1_700_000_000_000_000_000
    with McapRecorder(path, chunk_size=65536) as rec:
        n_pose = int(len(images) * period_s * 5) + 1
        for j in range(n_pose):
            if not odometry:
                break
            t = t0 + int(j * 0.2e9)
            odom = {"position": [10.0 * j * 0.2, 0.0, 30.0], "attitude": {"roll": 0.0, "pitch": 0.0, "yaw": 90.0},
                    "geodetic": {"lat": 52.0, "lon": 4.0, "alt": 30.0}}
            rec.write_json(f"/{robot}/odometry", t, odom, schema_name="aerodaas.Odometry")
            rec.write_pose(f"/{robot}/pose", t, odom["position"], 90.0, frame_id="enu")
        for i, img in enumerate(images):
            rec.write_image(f"/{robot}/camera/{sensor}", t0 + int(i * period_s * 1e9), img,
                            frame_id=f"{robot}/{sensor}")
    return path
