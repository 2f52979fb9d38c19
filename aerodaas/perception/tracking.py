"""Multi-object tracking with stable track ids: ByteTrack (Zhang, Sun, Jiang, Yu, Weng, Yuan, Luo, Liu, Wang,
"ByteTrack: Multi-Object Tracking by Associating Every Detection Box", ECCV 2022, Algorithm 1; reference code
``ifzhang/ByteTrack`` ``yolox/tracker/byte_tracker.py``), on our :class:`~aerodaas.model.types.Detection` boxes.

Per frame:

1. every track's box is predicted by a constant-velocity Kalman filter on ``(cx, cy, a, h)`` (centre, aspect
   ratio w/h, height; pixels), the filter and noise weights of SORT/DeepSORT (``kalman_filter.py``: position std
   ``h / 20``, velocity std ``h / 160``) that ByteTrack uses;
2. the *high* detections (score >= ``high_threshold``) are associated with every tracked and lost track by IoU
   (Hungarian, ``scipy.optimize.linear_sum_assignment``) when ``1 - IoU <= match_threshold`` (0.8);
3. the *low* detections (``low_threshold`` <= score < ``high_threshold``, the "BYTE" step that recovers occluded
   objects) are associated with the still unmatched tracked tracks at ``1 - IoU <= 0.5``; tracked tracks left
   unmatched become *lost*;
4. tracks born on the previous frame (unconfirmed) are matched with the remaining high detections at
   ``1 - IoU <= 0.7``, or removed;
5. remaining high detections with score >= ``new_track_threshold`` start new tracks (confirmed at once on the
   first frame of the tracker, as in the reference code); lost tracks not seen for ``track_buffer`` frames are
   removed; a lost track that is matched again keeps its id (re-acquisition).

Supervision's ByteTrack (``supervision`` on PyPI) would do, but it requires the ``opencv-python`` wheel, which
overwrites our ``opencv-python-headless`` cv2; the algorithm is ~150 lines on numpy and scipy.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aerodaas.perception.boxes import iou_matrix

from aerodaas.model.types import Detection

__all__ = ["ByteTrackConfig", "Track", "ByteTracker"]


@dataclass
class ByteTrackConfig:
    """ByteTrack thresholds (scores in [0, 1]; the paper's defaults are high 0.6 / new 0.7 for its
    YOLOX-X; nano COCO models from the air score lower, hence 0.3 / 0.35 here), ``match_threshold`` (max
    ``1 - IoU`` of the first association), ``track_buffer`` (frames a lost track is kept)."""

    high_threshold: float = 0.3
    low_threshold: float = 0.1
    new_track_threshold: float = 0.35
    match_threshold: float = 0.8
    track_buffer: int = 30

    def __post_init__(self) -> None:  # checked where the app writes it, and again in the pre-flight
        self.check()

    def check(self) -> None:
        """Raises ValueError naming the field and the value."""
        for f in ("high_threshold", "low_threshold", "new_track_threshold", "match_threshold"):
            v = getattr(self, f)
            if not isinstance(v, (int, float)) or not 0.0 <= float(v) <= 1.0:
                raise ValueError(f"tracker.{f} must be within [0, 1], got {v!r}")
        if self.low_threshold > self.high_threshold:
            raise ValueError(f"tracker.low_threshold={self.low_threshold} is above high_threshold="
                             f"{self.high_threshold}")
        if not isinstance(self.track_buffer, int) or self.track_buffer < 1:
            raise ValueError(f"tracker.track_buffer must be an integer >= 1 (frames), got {self.track_buffer!r}")


_STD_POS, _STD_VEL = 1.0 / 20, 1.0 / 160
_F = np.eye(8)
_F[:4, 4:] = np.eye(4)
_H = np.eye(4, 8)


def _xyah(box) -> np.ndarray:
    x0, y0, x1, y1 = box
    w, h = max(x1 - x0, 1e-3), max(y1 - y0, 1e-3)
    return np.array([(x0 + x1) / 2, (y0 + y1) / 2, w / h, h])


@dataclass
class Track:
    """One track: ``track_id`` (stable, from 1), ``detection`` (the last associated one), ``state`` (``tracked``,
    ``lost``, ``removed``), ``confirmed``, ``hits``, ``start_frame`` / ``last_frame`` (frame numbers), Kalman
    ``mean`` (8,) and ``cov`` (8, 8) on ``(cx, cy, a, h)`` and their velocities."""

    track_id: int
    detection: Detection
    mean: np.ndarray
    cov: np.ndarray
    state: str = "tracked"
    confirmed: bool = False
    hits: int = 1
    start_frame: int = 0
    last_frame: int = 0
    history: list = field(default_factory=list)

    @property
    def box(self) -> tuple[float, float, float, float]:
        """The Kalman box ``(x0, y0, x1, y1)`` pixels (predicted when not matched this frame)."""
        cx, cy, a, h = self.mean[:4]
        w = a * h
        return (float(cx - w / 2), float(cy - h / 2), float(cx + w / 2), float(cy + h / 2))

    def predict(self) -> None:
        h = self.mean[3]
        q = np.square(np.r_[_STD_POS * h, _STD_POS * h, 1e-2, _STD_POS * h,
                            _STD_VEL * h, _STD_VEL * h, 1e-5, _STD_VEL * h])
        if self.state != "tracked":
            self.mean[7] = 0.0  # as the reference: a lost track's height velocity is zeroed
        self.mean = _F @ self.mean
        self.cov = _F @ self.cov @ _F.T + np.diag(q)

    def update(self, det: Detection, frame: int) -> None:
        z = _xyah(det.box)
        h = self.mean[3]
        r = np.diag(np.square([_STD_POS * h, _STD_POS * h, 1e-1, _STD_POS * h]))
        s = _H @ self.cov @ _H.T + r
        k = self.cov @ _H.T @ np.linalg.inv(s)
        self.mean = self.mean + k @ (z - _H @ self.mean)
        self.cov = (np.eye(8) - k @ _H) @ self.cov
        self.detection, self.state, self.last_frame = det, "tracked", frame
        self.hits += 1
        self.confirmed = True


def _iou_cost(tracks: list[Track], dets: list[Detection]) -> np.ndarray:
    if not tracks or not dets:
        return np.zeros((len(tracks), len(dets)))
    return 1.0 - iou_matrix(np.array([t.box for t in tracks]), np.array([d.box for d in dets]))


def _assign(cost: np.ndarray, thresh: float) -> tuple[list[tuple[int, int]], list[int], list[int]]:
    from scipy.optimize import linear_sum_assignment  # lazy: heavy scipy

    if cost.size == 0:
        return [], list(range(cost.shape[0])), list(range(cost.shape[1]))
    rows, cols = linear_sum_assignment(cost)
    pairs = [(r, c) for r, c in zip(rows, cols) if cost[r, c] <= thresh]
    mr, mc = {r for r, _ in pairs}, {c for _, c in pairs}
    return pairs, [r for r in range(cost.shape[0]) if r not in mr], [c for c in range(cost.shape[1]) if c not in mc]


class ByteTracker:
    """ByteTrack over the frames of **one** camera (keep one per drone: an analytics shared by a fleet holds one in
    each drone's state). :meth:`update` takes the frame's detections (pixel boxes, any score) and returns the
    tracks that are tracked and confirmed on this frame, each with its stable ``track_id``."""

    def __init__(self, config: ByteTrackConfig | None = None) -> None:
        self.config = config or ByteTrackConfig()
        self.config.check()
        self.frame = 0
        self.next_id = 1
        self.tracks: list[Track] = []

    def update(self, detections: list[Detection]) -> list[Track]:
        """Advance one frame with ``detections``; returns the active (tracked, confirmed) tracks, by id."""
        c = self.config
        self.frame += 1
        high = [d for d in detections if d.score >= c.high_threshold]
        low = [d for d in detections if c.low_threshold <= d.score < c.high_threshold]
        confirmed = [t for t in self.tracks if t.confirmed and t.state in ("tracked", "lost")]
        unconfirmed = [t for t in self.tracks if not t.confirmed and t.state == "tracked"]
        for t in confirmed + unconfirmed:
            t.predict()
        # 1st association: high detections x (tracked + lost) confirmed tracks
        pairs, um_t, um_d = _assign(_iou_cost(confirmed, high), c.match_threshold)
        for ti, di in pairs:
            confirmed[ti].update(high[di], self.frame)
        rest_high = [high[i] for i in um_d]
        # 2nd association (BYTE): low detections x still-unmatched tracked tracks
        left = [confirmed[i] for i in um_t if confirmed[i].state == "tracked"]
        pairs2, um_t2, _ = _assign(_iou_cost(left, low), 0.5)
        for ti, di in pairs2:
            left[ti].update(low[di], self.frame)
        for i in um_t2:
            left[i].state = "lost"
        # unconfirmed tracks x remaining high detections
        pairs3, um_u, um_d3 = _assign(_iou_cost(unconfirmed, rest_high), 0.7)
        for ti, di in pairs3:
            unconfirmed[ti].update(rest_high[di], self.frame)
        for i in um_u:
            unconfirmed[i].state = "removed"
        for i in um_d3:
            d = rest_high[i]
            if d.score < c.new_track_threshold:
                continue
            z = _xyah(d.box)
            h = z[3]
            cov = np.diag(np.square([2 * _STD_POS * h, 2 * _STD_POS * h, 1e-2, 2 * _STD_POS * h,
                                     10 * _STD_VEL * h, 10 * _STD_VEL * h, 1e-5, 10 * _STD_VEL * h]))
            self.tracks.append(Track(self.next_id, d, np.r_[z, np.zeros(4)], cov, confirmed=self.frame == 1,
                                     start_frame=self.frame, last_frame=self.frame))
            self.next_id += 1
        for t in self.tracks:
            if t.state == "lost" and self.frame - t.last_frame > c.track_buffer:
                t.state = "removed"
        self.tracks = [t for t in self.tracks if t.state != "removed"]
        return sorted((t for t in self.tracks if t.state == "tracked" and t.confirmed and t.last_frame == self.frame),
                      key=lambda t: t.track_id)
