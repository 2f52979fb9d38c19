"""Camera frames out of MCAP recordings, video files and image lists, decoded one at a time (bounded memory).

* :class:`McapSource`: every ``foxglove.CompressedImage`` channel of a recording made by ``aerodaas run --record``
  (the recorder writes camera ``<sensor>`` of robot ``<robot>`` on ``/<robot>/camera/<sensor>``; the camera is
  named ``<robot>-<sensor>``), each frame with the robot's pose nearest in time: the ``aerodaas.Odometry`` JSON of
  ``/<robot>/odometry`` (ENU position in metres, attitude and WGS-84 fix), else the ``foxglove.PoseInFrame`` of
  ``/<robot>/pose``.
* :class:`VideoSource`: the first video stream of a file PyAV (FFmpeg) decodes; the camera is named ``video``.
* :class:`ImageListSource`: image files already extracted (one flight), read with OpenCV; the camera is ``img``.

Every source has ``flight``, ``source`` (the file), :meth:`check` (raises :class:`LabelInputError` naming the file
when it holds no frame that can be decoded) and ``frames(want)``, which yields ``(FrameRef, image)`` for every frame
whose :class:`FrameRef` ``want`` accepts (images ``(H, W, 3) uint8 BGR``); a frame not wanted is not converted to
pixels. Frame numbers count a camera's frames from 0 in decode (recording: log-time) order.
"""
from __future__ import annotations

import bisect
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import av
import cv2
import numpy as np

from aerodaas.labelling.names import clean_name, flight_of, frame_name
from aerodaas.recording.reader import read_messages, summarize_mcap

__all__ = ["LabelInputError", "FrameRef", "McapSource", "VideoSource", "ImageListSource", "open_source",
           "IMAGE_SCHEMA"]

#: the schema of a recorded camera channel
IMAGE_SCHEMA = "foxglove.CompressedImage"


class LabelInputError(ValueError):
    """Bad input to ``aerodaas label``: the message names the file, option or value (the CLI exits 2)."""


@dataclass(frozen=True)
class FrameRef:
    """One frame: ``flight`` and ``camera`` (cleaned names), ``index`` (the camera's frame number from 0),
    ``t_s`` (seconds since the recording's first message or the video's first frame; None for an image list),
    ``source`` (the file it was read from) and ``pose`` (the vehicle's pose nearest in time, a JSON-able dict, or
    None)."""

    flight: str
    camera: str
    index: int
    t_s: float | None
    source: str
    pose: dict | None = field(default=None, compare=False, hash=False)

    @property
    def key(self) -> tuple[str, str, int]:
        """``(flight, camera, index)``: unique among the frames of one selection."""
        return self.flight, self.camera, self.index

    @property
    def name(self) -> str:
        """The file stem the frame is written under (:func:`aerodaas.labelling.names.frame_name`)."""
        return frame_name(self.flight, self.camera, self.index)


Want = Callable[[FrameRef], bool]


def camera_of_topic(topic: str) -> str:
    """The camera name of a recorded camera topic: ``/drone1/camera/cam0`` -> ``drone1-cam0``."""
    return clean_name(topic.replace("/camera/", "/"), "cam")


class _Poses:
    """A robot's recorded poses: times (ns, sorted) and the pose dicts, for the nearest-in-time look-up."""

    def __init__(self) -> None:
        self.t_ns: list[int] = []
        self.poses: list[dict] = []

    def add(self, t_ns: int, pose: dict) -> None:
        self.t_ns.append(int(t_ns))
        self.poses.append(pose)

    def nearest(self, t_ns: int, start_ns: int) -> dict | None:
        if not self.t_ns:
            return None
        i = bisect.bisect_left(self.t_ns, t_ns)
        best = min((j for j in (i - 1, i) if 0 <= j < len(self.t_ns)), key=lambda j: abs(self.t_ns[j] - t_ns))
        return {**self.poses[best], "t_s": (self.t_ns[best] - start_ns) / 1e9,
                "dt_s": (self.t_ns[best] - t_ns) / 1e9}


def _odometry_pose(msg: Any) -> dict | None:
    if not isinstance(msg, dict):
        return None
    out = {"topic_kind": "odometry"}
    for k in ("position", "attitude", "geodetic", "velocity"):
        if k in msg:
            out[k] = msg[k]
    return out


def _proto_pose(msg: Any) -> dict:
    p, q = msg.pose.position, msg.pose.orientation
    return {"topic_kind": "pose", "frame_id": msg.frame_id, "position": [p.x, p.y, p.z],
            "orientation_xyzw": [q.x, q.y, q.z, q.w]}


class McapSource:
    """The camera channels of an AeroDaaS MCAP recording (module docstring). ``flight``: default the file's
    cleaned stem. Raises :class:`LabelInputError` (from :meth:`check`, or the constructor for a file that is not
    an MCAP recording) naming the file and the channels it has when it has no camera channel with messages."""

    def __init__(self, path: str | os.PathLike, flight: str | None = None) -> None:
        self.source = str(path)
        self.flight = clean_name(flight, "flight") if flight else flight_of(path)
        try:
            summary = summarize_mcap(self.source)
        except (OSError, ValueError) as e:
            raise LabelInputError(f"recording {self.source!r}: cannot be read ({e})") from None
        self.start_ns = int(summary["start_ns"] or 0)
        chans = summary["channels"]
        self.topics = sorted({c["topic"] for c in chans if c["schema"] == IMAGE_SCHEMA and c["count"] > 0})
        self._all_topics = [f"{c['topic']} ({c['schema'] or c['encoding']})" for c in chans]
        have = {c["topic"]: c["schema"] for c in chans if c["count"] > 0}
        self._pose_topics: dict[str, str] = {}
        for robot in sorted({t.strip("/").split("/")[0] for t in self.topics}):
            if have.get(f"/{robot}/odometry"):
                self._pose_topics[f"/{robot}/odometry"] = robot
            elif have.get(f"/{robot}/pose") == "foxglove.PoseInFrame":
                self._pose_topics[f"/{robot}/pose"] = robot
        self._poses: dict[str, _Poses] | None = None

    def check(self) -> None:
        """Raises :class:`LabelInputError` when the recording has no camera channel with messages."""
        if not self.topics:
            raise LabelInputError(f"recording {self.source!r}: no camera channel ({IMAGE_SCHEMA} with messages); "
                                  f"its channels: {self._all_topics or 'none'}")

    def _load_poses(self) -> dict[str, _Poses]:
        if self._poses is None:
            self._poses = {robot: _Poses() for robot in self._pose_topics.values()}
            if self._pose_topics:
                for topic, _schema, t_ns, msg in read_messages(self.source, topics=list(self._pose_topics)):
                    pose = _odometry_pose(msg) if topic.endswith("/odometry") else _proto_pose(msg)
                    if pose is not None:
                        self._poses[self._pose_topics[topic]].add(t_ns, pose)
            for p in self._poses.values():  # unfinished files come in write order
                order = np.argsort(np.asarray(p.t_ns, np.int64), kind="stable")
                p.t_ns = [p.t_ns[i] for i in order]
                p.poses = [p.poses[i] for i in order]
        return self._poses

    def frames(self, want: Want) -> Iterator[tuple[FrameRef, np.ndarray]]:
        """``(FrameRef, (H, W, 3) uint8 BGR)`` for each wanted frame, in log-time order. Raises
        :class:`LabelInputError` for a wanted frame whose bytes do not decode."""
        poses = self._load_poses()
        counts = dict.fromkeys(self.topics, 0)
        for topic, _schema, t_ns, msg in read_messages(self.source, topics=self.topics):
            index = counts[topic]
            counts[topic] += 1
            robot = topic.strip("/").split("/")[0]
            pose = poses[robot].nearest(t_ns, self.start_ns) if robot in poses else None
            ref = FrameRef(self.flight, camera_of_topic(topic), index, (t_ns - self.start_ns) / 1e9, self.source,
                           pose)
            if not want(ref):
                continue
            img = cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_COLOR)
            if img is None:
                raise LabelInputError(f"recording {self.source!r}: frame {index} of {topic} does not decode "
                                      f"(format {msg.format!r})")
            yield ref, img


class VideoSource:
    """The first video stream of a video file (PyAV), decoded frame by frame. ``flight``: default the file's
    cleaned stem; the camera is ``video``. :meth:`check` raises :class:`LabelInputError` naming the file when it
    cannot be opened, has no video stream or no frame decodes."""

    camera = "video"

    def __init__(self, path: str | os.PathLike, flight: str | None = None) -> None:
        self.source = str(path)
        self.flight = clean_name(flight, "flight") if flight else flight_of(path)

    def check(self) -> None:
        """Decode the first frame (raises :class:`LabelInputError` when there is none)."""
        for _ in self.frames(lambda ref: False, _stop_after=1):
            pass

    def frames(self, want: Want, _stop_after: int | None = None) -> Iterator[tuple[FrameRef, np.ndarray]]:
        """``(FrameRef, (H, W, 3) uint8 BGR)`` for each wanted frame, in decode order; ``t_s`` from the frame's
        presentation time (its number over the stream's average rate when it has none). Raises
        :class:`LabelInputError` when the file does not decode."""
        n = 0
        try:
            with av.open(self.source) as box:
                if not box.streams.video:
                    raise LabelInputError(f"video {self.source!r}: no video stream")
                stream = box.streams.video[0]
                stream.thread_type = "AUTO"  # FFmpeg's frame and slice threads
                rate = float(stream.average_rate) if stream.average_rate else 0.0
                t0 = None
                for frame in box.decode(stream):
                    t = frame.time
                    if t is None:
                        t = n / rate if rate > 0 else None
                    if t is not None:
                        t0 = t if t0 is None else t0
                        t = float(t - t0)
                    ref = FrameRef(self.flight, self.camera, n, t, self.source)
                    n += 1
                    if want(ref):
                        yield ref, frame.to_ndarray(format="bgr24")
                    if _stop_after is not None and n >= _stop_after:
                        return
        except (av.error.FFmpegError, OSError, ValueError) as e:
            if isinstance(e, LabelInputError):
                raise
            raise LabelInputError(f"video {self.source!r}: cannot be decoded ({type(e).__name__}: {e})") from None
        if n == 0:
            raise LabelInputError(f"video {self.source!r}: no frame decodes")


class ImageListSource:
    """Images already extracted, one flight: ``paths`` in frame order (frame number = position in the list);
    the camera is ``img``. :meth:`check` raises :class:`LabelInputError` naming a path that is not a file."""

    camera = "img"

    def __init__(self, paths: Sequence[str | os.PathLike], flight: str) -> None:
        self.paths = [str(p) for p in paths]
        self.flight = clean_name(flight, "flight")
        self.source = self.paths[0] if self.paths else ""

    def check(self) -> None:
        """Raises :class:`LabelInputError` for an empty list or a path that is not a file."""
        if not self.paths:
            raise LabelInputError(f"flight {self.flight!r}: no image")
        for p in self.paths:
            if not Path(p).is_file():
                raise LabelInputError(f"image {p!r} (flight {self.flight!r}): no such file")

    def frames(self, want: Want) -> Iterator[tuple[FrameRef, np.ndarray]]:
        """``(FrameRef, (H, W, 3) uint8 BGR)`` for each wanted image (``source`` is the image's own path);
        raises :class:`LabelInputError` for an image OpenCV cannot read."""
        for i, p in enumerate(self.paths):
            ref = FrameRef(self.flight, self.camera, i, None, p)
            if not want(ref):
                continue
            img = cv2.imread(p, cv2.IMREAD_COLOR)
            if img is None:
                raise LabelInputError(f"image {p!r} (flight {self.flight!r}): cannot be read as an image")
            yield ref, img


#: file suffixes read as MCAP recordings; anything else is tried as a video
MCAP_SUFFIXES = (".mcap",)


def open_source(path: str | os.PathLike) -> McapSource | VideoSource:
    """The source of one input file: :class:`McapSource` for ``*.mcap``, else :class:`VideoSource`. Raises
    :class:`LabelInputError` when ``path`` is not a file."""
    p = Path(path)
    if not p.is_file():
        raise LabelInputError(f"input {str(p)!r}: no such file")
    return McapSource(p) if p.suffix.lower() in MCAP_SUFFIXES else VideoSource(p)
