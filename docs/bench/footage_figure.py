"""Draw the picture of docs/results/tracking.md's "Real footage over RTSP" section from a run's recording.

    python docs/bench/footage_figure.py RUN.mcap OUT.png [--robot quadrotor_base] [--track ID]

Left: one camera frame of the run (the recorded JPEG from the middle of the run) with the detector's boxes on it
(red), the follow analytics' track boxes with their ids (green), and the chosen track's box centres over the whole
run (yellow: its path in the image). Right: that track's geo-located fixes (``/<robot>/follow/tracks/fixes``,
WGS-84; orange) and the drone's own GPS fixes (``/<robot>/gps``; grey) as metres east/north of the track's first
fix: its path on the map beside the drone's. ``--track`` picks the track id (default: the id recorded on the most
frames). Needs OpenCV, numpy and Pillow (matplotlib's dependency: the PNG is written with a 96-colour palette to
stay small); reads the MCAP with ``aerodaas.recording.reader``. Raises SystemExit naming what is missing from the
recording."""
from __future__ import annotations

import argparse
import math
from collections import Counter

import cv2
import numpy as np

from aerodaas.recording.reader import read_messages


def _boxes(ann) -> list[tuple[tuple[float, float, float, float], dict[str, str]]]:
    out = []
    for p in ann.points:
        xs, ys = [q.x for q in p.points], [q.y for q in p.points]
        if xs:
            out.append(((min(xs), min(ys), max(xs), max(ys)), {kv.key: kv.value for kv in p.metadata}))
    return out


def read(rec: str, robot: str) -> dict:
    """Frames (log time -> JPEG bytes), detections and tracks per log time, and track fixes (id -> [(lat, lon)])."""
    got: dict = {"frames": {}, "dets": {}, "tracks": {}, "fixes": {}, "drone": []}
    for topic, schema, t, msg in read_messages(rec):
        if topic == f"/{robot}/camera/cam1" and schema == "foxglove.CompressedImage":
            got["frames"][t] = bytes(msg.data)
        elif topic == f"/{robot}/detector/detections" and schema == "foxglove.ImageAnnotations":
            got["dets"][t] = [b for b, _ in _boxes(msg)]
        elif topic == f"/{robot}/follow/tracks" and schema == "foxglove.ImageAnnotations":
            got["tracks"][t] = {int(m["track_id"]): b for b, m in _boxes(msg)}
        elif topic == f"/{robot}/gps" and schema == "foxglove.LocationFix":
            got["drone"].append((msg.latitude, msg.longitude))
        elif topic == f"/{robot}/follow/tracks/fixes" and schema == "foxglove.LocationFixes":
            for fix in msg.fixes:
                meta = {kv.key: kv.value for kv in fix.metadata}
                got["fixes"].setdefault(int(meta["track_id"]), []).append((fix.latitude, fix.longitude))
    for key in ("frames", "dets", "tracks"):
        if not got[key]:
            raise SystemExit(f"{rec}: no {key} recorded for robot {robot!r}")
    return got


def _map_panel(fixes: list[tuple[float, float]], drone: list[tuple[float, float]], size: int, tid: int
               ) -> np.ndarray:
    """The track's ``fixes`` (orange) and the ``drone``'s (grey), (lat, lon) degrees, as metres east/north of the
    track's first fix, scaled to fit a ``size`` px square, on a grid of 1, 2, 5, 10 or 20 m."""
    panel = np.full((size, size, 3), 255, np.uint8)
    lat0, lon0 = fixes[0]
    k = 6371000.0 * math.pi / 180.0  # metres per degree of latitude (spherical Earth: a figure, not a survey)

    def en(pts):
        return np.array([((lon - lon0) * k * math.cos(math.radians(lat0)), (lat - lat0) * k) for lat, lon in pts])

    track, path = en(fixes), en(drone) if drone else np.zeros((0, 2))
    both = np.vstack([track, path])
    centre = (both.min(0) + both.max(0)) / 2
    half = max(2.0, float(np.abs(both - centre).max()) * 1.1)
    step = next(g for g in (1, 2, 5, 10, 20, 50) if 2 * half / g <= 12)

    def px(e, n):
        return int(size / 2 + (e - centre[0]) / half * size / 2), int(size / 2 - (n - centre[1]) / half * size / 2)

    for m in np.arange(math.floor((centre[0] - half) / step) * step, centre[0] + half + step, step):
        cv2.line(panel, (px(m, 0)[0], 0), (px(m, 0)[0], size), (225, 225, 225), 1)
    for m in np.arange(math.floor((centre[1] - half) / step) * step, centre[1] + half + step, step):
        cv2.line(panel, (0, px(0, m)[1]), (size, px(0, m)[1]), (225, 225, 225), 1)
    for pts, colour in ((path, (150, 150, 150)), (track, (0, 140, 255))):
        if len(pts) > 1:
            cv2.polylines(panel, [np.array([px(e, n) for e, n in pts], np.int32)], False, colour, 1, cv2.LINE_AA)
    cv2.putText(panel, f"track #{tid}: {len(fixes)} fixes (orange); drone GPS (grey)", (8, 20),
                cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(panel, f"north up, grid {step} m", (8, size - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (80, 80, 80), 1,
                cv2.LINE_AA)
    return panel


def draw(rec: str, out: str, robot: str = "quadrotor_base", track: int | None = None) -> dict:
    """Write the figure to ``out`` (PNG); returns what it drew (frame time, track id, fix and box counts)."""
    got = read(rec, robot)
    counts = Counter(tid for frame in got["tracks"].values() for tid in frame)
    tid = track if track is not None else counts.most_common(1)[0][0]
    times = sorted(t for t in got["frames"] if t in got["dets"] and t in got["tracks"])
    if not times:
        raise SystemExit(f"{rec}: no camera frame with both detections and tracks at its log time")
    t = times[len(times) // 2]
    img = cv2.imdecode(np.frombuffer(got["frames"][t], np.uint8), cv2.IMREAD_COLOR)
    centres = [((b[0] + b[2]) / 2, (b[1] + b[3]) / 2) for frame in (got["tracks"][k] for k in sorted(got["tracks"]))
               for i, b in frame.items() if i == tid]
    for b in got["dets"][t]:
        cv2.rectangle(img, (int(b[0]) - 2, int(b[1]) - 2), (int(b[2]) + 2, int(b[3]) + 2), (0, 0, 255), 1)
    for i, b in got["tracks"][t].items():
        cv2.rectangle(img, (int(b[0]), int(b[1])), (int(b[2]), int(b[3])), (0, 200, 0), 1)
        cv2.putText(img, f"#{i}", (int(b[0]), int(b[1]) - 3), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 255, 0), 1)
    if len(centres) > 1:
        cv2.polylines(img, [np.array(centres, np.int32)], False, (0, 255, 255), 1, cv2.LINE_AA)
    cv2.putText(img, f"detections (red), tracks (green), track #{tid} centres over the run (yellow)", (6, 16),
                cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1, cv2.LINE_AA)
    fixes = got["fixes"].get(tid, [])
    right = _map_panel(fixes, got["drone"], img.shape[0], tid) if fixes else np.full_like(img[:, :img.shape[0]], 255)
    from PIL import Image

    rgb = cv2.cvtColor(np.hstack([img, right]), cv2.COLOR_BGR2RGB)
    Image.fromarray(rgb).quantize(colors=96).save(out, optimize=True)
    return {"frame_time_ns": t, "track_id": tid, "track_frames": counts[tid], "fixes": len(fixes),
            "boxes": len(got["dets"][t])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording")
    ap.add_argument("out")
    ap.add_argument("--robot", default="quadrotor_base")
    ap.add_argument("--track", type=int, default=None)
    a = ap.parse_args()
    print(draw(a.recording, a.out, a.robot, a.track))


if __name__ == "__main__":
    main()
