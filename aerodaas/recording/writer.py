"""Mission recording to MCAP files (Foxglove-compatible).

A :class:`McapRecorder` writes one drone mission to an `MCAP <https://mcap.dev>`_ file that opens directly in
Foxglove Studio:

* camera frames, detections, GPS fixes, poses and transforms use Foxglove's well-known **protobuf** schemas
  (``foxglove.CompressedImage``, ``foxglove.ImageAnnotations``, ``foxglove.LocationFix``,
  ``foxglove.PoseInFrame``, ``foxglove.FrameTransform``; message encoding ``"protobuf"``, schema encoding
  ``"protobuf"``);
* AeroDaaS' own messages (mission state, telemetry, results, ...) are **JSON** channels (message encoding
  ``"json"``, schema encoding ``"jsonschema"``).

Conventions:

* every timestamp is an ``int`` of **nanoseconds** (``log_time_ns``; the MCAP ``publish_time`` is set to the
  same value and the protobuf ``timestamp`` fields are derived from it);
* angles are **degrees**; local positions are ENU metres; latitude/longitude are WGS-84 degrees, altitude metres;
* images are ``(H, W, 3) uint8`` **BGR** arrays (OpenCV order); detection boxes are pixel ``(x0, y0, x1, y1)``
  with the origin at the top-left corner of the image.

Topic conventions used by other AeroDaaS code: ``"/mission/state"`` (JSON dict with key ``"state"``),
``"/mission/result"`` (JSON dict with key ``"outcome"``, e.g. ``"success"``), ``"/tf"`` (transforms).

Crash safety: messages are grouped into compressed chunks of about ``chunk_size`` bytes. Each chunk is handed to
the operating system (``file.flush()``) as soon as it is complete, and :meth:`McapRecorder.flush` closes the chunk
in progress and flushes it too. If the recording process dies without :meth:`McapRecorder.close`, the file lacks
its summary/footer but every completed chunk is still readable with
:func:`~aerodaas.recording.reader.read_messages` and :func:`~aerodaas.recording.reader.summarize_mcap` (which report
``finished=False``); at most the unfinished last chunk is lost.

Reading a recording is :mod:`aerodaas.recording.reader`'s: ``summarize_mcap`` (what ``aerodaas info FILE.mcap``
prints) and ``read_messages``.

The stream between mcap's writer and the file is :class:`aerodaas.recording.chunk_stream.ChunkFlushingStream`; the
checks of where a recording may be written (``check_record_path``, ``is_aerodaas_recording``) are in
:mod:`aerodaas.recording.record_path`.
"""
from __future__ import annotations

import importlib
import json
import math
import os
import threading
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Callable, NamedTuple

import cv2
import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.KeyValuePair_pb2 import KeyValuePair
from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
from foxglove_schemas_protobuf.Point2_pb2 import Point2
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.TextAnnotation_pb2 import TextAnnotation
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from mcap.writer import CompressionType
from mcap.writer import Writer as _McapWriter
from mcap_protobuf.schema import build_file_descriptor_set

from aerodaas.recording.reader import METADATA_NAME
from aerodaas.model.types import Detection
from aerodaas.recording.chunk_stream import ChunkFlushingStream
from aerodaas.recording.record_path import LIBRARY
from aerodaas.recording.schemas import json_schema_for, plugin_json_schemas
from aerodaas.recording.values import (_check_time, _class_color, _detection_fields, _finite, _jsonable, _timestamp,
                                      _vec3, quaternion_from_euler_deg)

__all__ = ["McapRecorder", "RecordedMessage", "TF_TOPIC"]

TF_TOPIC = "/tf"
"""Conventional topic for ``foxglove.FrameTransform`` messages."""

_PERMISSIVE_SCHEMA: dict[str, Any] = {"type": "object"}
try:  # zstd chunks when zstandard is there (a dependency of mcap)
    import zstandard  # noqa: F401

    _COMPRESSION = CompressionType.ZSTD
except ImportError:  # pragma: no cover
    _COMPRESSION = CompressionType.NONE


class RecordedMessage(NamedTuple):
    """One message exactly as written to the MCAP file, handed to every sink of a :class:`McapRecorder`
    (:meth:`McapRecorder.add_sink`; e.g. the live Foxglove WebSocket server of :mod:`aerodaas.liveview.server`): the topic,
    its schema record (name, encoding ``"protobuf"``/``"jsonschema"``, bytes: a FileDescriptorSet or a JSON
    Schema), the message encoding (``"protobuf"``/``"json"``), log time (ns) and the serialized bytes."""

    topic: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    message_encoding: str
    log_time_ns: int
    data: bytes


# --------------------------------------------------------------------------------------------------------------
# writer
# --------------------------------------------------------------------------------------------------------------
class McapRecorder:
    """Records one mission to an MCAP file (plain Python class; AeroDaaS wraps it in a Ray actor).

    Args:
        path: output file; its parent directory is created if missing; an existing file is overwritten.
            ``None``: no file (messages are serialized for the sinks only, e.g. a live view without a recording).
        chunk_size: target uncompressed chunk size in bytes (a chunk is closed, compressed with zstd and flushed
            to the OS once it grows past this). Smaller chunks lose less data on a crash; larger ones compress
            better. Must be > 0.
        jpeg_quality: JPEG quality 0-100 used by :meth:`write_image` when given a raw BGR array.
        metadata: string key/values stored as an MCAP metadata record named ``"aerodaas"`` (values are ``str()``-ed).
        json_schemas: the plug-ins' message schemas (schema name -> JSON Schema dict), the schema of their JSON
            channels (:meth:`write_json`); the recorder owns them (no process-wide table).

    Raises:
        OSError (e.g. ``PermissionError``, ``IsADirectoryError``): the file cannot be created; the message names
            the path.
        ValueError: ``chunk_size <= 0``, ``jpeg_quality`` outside 0-100, or a ``json_schemas`` name that is built
            in (:func:`aerodaas.recording.schemas.plugin_json_schemas`).

    Every ``write_*`` method takes ``topic`` and ``log_time_ns`` (``int`` nanoseconds, ``0 <= t < 2**64``;
    publish time = log time). A topic's channel is created on first use and keeps its message kind: writing a
    different kind (another protobuf type, or protobuf vs JSON, or another JSON ``schema_name``) raises
    ``ValueError`` naming the topic. After :meth:`close`, writes raise ``RuntimeError``. All methods are
    thread-safe (one internal lock). ``message_counts`` maps topic -> messages written.
    """

    def __init__(self, path: str | os.PathLike | None, *, chunk_size: int = 256 * 1024, jpeg_quality: int = 85,
                 metadata: dict[str, str] | None = None,
                 json_schemas: Mapping[str, Mapping[str, Any]] | None = None) -> None:
        if int(chunk_size) <= 0:
            raise ValueError(f"chunk_size must be a positive number of bytes, got {chunk_size!r}")
        if not 0 <= int(jpeg_quality) <= 100:
            raise ValueError(f"jpeg_quality must be within [0, 100], got {jpeg_quality!r}")
        self.path = Path(path if path is not None else os.devnull)
        self.chunk_size = int(chunk_size)
        self.jpeg_quality = int(jpeg_quality)
        self.message_counts: dict[str, int] = {}
        self._lock = threading.Lock()
        self._closed = False
        self._channels: dict[str, int] = {}  # topic -> channel id
        self._topic_kind: dict[str, str] = {}  # topic -> "protobuf:<type>" | "json:<schema_name>"
        self._schema_ids: dict[Any, int] = {}  # schema cache key -> schema id
        self._schema_records: dict[str, tuple[str, str, bytes]] = {}  # topic -> (name, encoding, data)
        self._sinks: list[Callable[[RecordedMessage], None]] = []
        self._default_schema_text: dict[str, str] = {}  # topic -> its generated JSON Schema (write_json)
        #: the plug-ins' message schemas (schema name -> JSON Schema), checked: a built-in name raises ValueError
        self._plugin_schemas = plugin_json_schemas(json_schemas)
        self.sink_errors: list[str] = []
        self._sequence: int | None = None  # set_sequence: the producer's number for the messages that follow
        try:
            if path is not None:
                self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        except OSError as e:
            raise OSError(e.errno, f"cannot open MCAP recording file for writing ({e.strerror or e})",
                          str(self.path)) from e
        self._stream = ChunkFlushingStream(self._file)
        try:
            self._writer = _McapWriter(self._stream, chunk_size=self.chunk_size,
                                       compression=_COMPRESSION if path is not None else CompressionType.NONE)
            self._writer.start(profile="", library=LIBRARY)
            if metadata:
                self._writer.add_metadata(METADATA_NAME, {str(k): str(v) for k, v in metadata.items()})
            self._stream.sync()
        except BaseException:
            self._file.close()
            raise

    # ---------------------------------------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        """True once :meth:`close` has been called."""
        return self._closed

    def __enter__(self) -> "McapRecorder":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"McapRecorder({str(self.path)!r}, {state}, {sum(self.message_counts.values())} messages)"

    # ---------------------------------------------------------------------------------------------------------
    def _channel_for(self, topic: str, kind: str, make_schema: Any, schema_key: Any, message_encoding: str) -> int:
        """Channel id for ``topic``, registering schema/channel on first use. Caller holds the lock."""
        if not isinstance(topic, str) or not topic:
            raise ValueError(f"topic must be a non-empty string, got {topic!r}")
        existing = self._topic_kind.get(topic)
        if existing is not None:
            if existing != kind:
                raise ValueError(f"topic {topic!r} already carries {existing}; cannot write {kind} to it "
                                 f"(one topic keeps one schema)")
            return self._channels[topic]
        schema_id = self._schema_ids.get(schema_key)
        record = make_schema()
        if schema_id is None:
            name, encoding, data = record
            schema_id = self._writer.register_schema(name=name, encoding=encoding, data=data)
            self._schema_ids[schema_key] = schema_id
        self._schema_records[topic] = record
        channel_id = self._writer.register_channel(topic=topic, message_encoding=message_encoding,
                                                   schema_id=schema_id)
        self._channels[topic] = channel_id
        self._topic_kind[topic] = kind
        return channel_id

    def _write(self, topic: str, log_time_ns: int, kind: str, make_schema: Any, schema_key: Any,
               message_encoding: str, data: bytes) -> None:
        with self._lock:
            if self._closed:
                raise RuntimeError(f"McapRecorder for {str(self.path)!r} is closed; cannot write to {topic!r}")
            channel_id = self._channel_for(topic, kind, make_schema, schema_key, message_encoding)
            self._writer.add_message(channel_id=channel_id, log_time=log_time_ns, data=data,
                                     publish_time=log_time_ns,
                                     sequence=(self.message_counts.get(topic, 0) if self._sequence is None
                                               else self._sequence) & 0xFFFFFFFF)
            self.message_counts[topic] = self.message_counts.get(topic, 0) + 1
            # A completed chunk was just written to the stream: hand it to the OS so it survives a crash.
            self._stream.sync()
            if self._sinks:
                self._to_sinks(RecordedMessage(topic, *self._schema_records[topic], message_encoding, log_time_ns,
                                               data))

    def set_sequence(self, seq: int | None) -> None:
        """Write ``seq`` as the MCAP ``sequence`` of the messages that follow (the producer's number of the item
        they come from, :class:`~aerodaas.protocol.messages.RecordItem`; messages derived from one item, e.g. an
        odometry sample's pose, fix and transforms, share it); None: each topic's own count of written messages
        (the default). MCAP's Message.sequence is "an optional message counter assigned by the publisher, to
        detect message gaps" (MCAP specification, Message record), 32 bits: wraps at 2**32."""
        self._sequence = None if seq is None else int(seq)

    def add_sink(self, sink: Callable[[RecordedMessage], None]) -> None:
        """Also hand every message written from now on to ``sink`` (called in the writing thread, under the
        recorder's lock, right after the message went to the file: it must return quickly). The bytes are the
        ones written to the file, so a sink shows exactly the recording's channels, schemas and messages. A sink
        that raises is removed and its error kept in ``sink_errors``: it never stops the recording."""
        with self._lock:
            self._sinks.append(sink)

    def _to_sinks(self, msg: RecordedMessage) -> None:
        for sink in list(self._sinks):
            try:
                sink(msg)
            except Exception as e:  # a failing live view must never cost the recording
                self._sinks.remove(sink)
                self.sink_errors.append(f"{type(e).__name__}: {e}")

    def write_proto(self, topic: str, log_time_ns: int, msg: Any) -> None:
        """Write one protobuf message (any Foxglove schema) on ``topic`` at ``log_time_ns`` (ns since the epoch);
        the channel and its schema are registered on first use."""
        cls = type(msg)
        full_name = cls.DESCRIPTOR.full_name

        def make_schema() -> tuple[str, str, bytes]:
            return full_name, "protobuf", build_file_descriptor_set(cls).SerializeToString()

        self._write(topic, log_time_ns, f"protobuf:{full_name}", make_schema, ("protobuf", full_name),
                    "protobuf", msg.SerializeToString())

    def declare_proto(self, topic: str, schema_name: str) -> tuple[str, str, bytes]:
        """Register ``topic`` for the Foxglove protobuf schema ``schema_name`` (e.g. ``"foxglove.SceneUpdate"``)
        before its first message, so the channel is in the file (and can be advertised live) from the start;
        returns its schema record ``(name, "protobuf", FileDescriptorSet bytes)``. Raises ``ValueError`` for a
        name that is not a Foxglove schema or a topic that already carries another kind."""
        pkg, _, short = schema_name.partition(".")
        try:
            if pkg != "foxglove" or not short.isidentifier():
                raise ImportError
            cls = getattr(importlib.import_module(f"foxglove_schemas_protobuf.{short}_pb2"), short)
        except (ImportError, AttributeError):
            raise ValueError(f"declare_proto({topic!r}): {schema_name!r} is not a foxglove protobuf schema") from None

        def make_schema() -> tuple[str, str, bytes]:
            return schema_name, "protobuf", build_file_descriptor_set(cls).SerializeToString()

        with self._lock:
            if self._closed:
                raise RuntimeError(f"McapRecorder for {str(self.path)!r} is closed; cannot declare {topic!r}")
            self._channel_for(topic, f"protobuf:{schema_name}", make_schema, ("protobuf", schema_name), "protobuf")
            self._stream.sync()
            return self._schema_records[topic]

    # ---------------------------------------------------------------------------------------------------------
    def write_image(self, topic: str, log_time_ns: int, image_bgr: np.ndarray | None = None, *,
                    jpeg: bytes | None = None, frame_id: str = "camera") -> None:
        """Write a ``foxglove.CompressedImage`` (format ``"jpeg"``).

        Give exactly one of ``image_bgr`` (``(H, W, 3) uint8`` BGR array, encoded with ``cv2.imencode('.jpg')``
        at ``jpeg_quality``; ``(H, W)`` grayscale is accepted too) or ``jpeg`` (already-encoded JPEG bytes,
        written as is). ``frame_id`` names the camera frame.

        Raises ``ValueError`` for a missing/duplicate image argument, a wrong shape or dtype, a failed encode
        or ``jpeg`` bytes without the JPEG start marker; ``RuntimeError`` after close; ``ValueError`` if ``topic`` carries another kind.
        """
        t = _check_time(log_time_ns)
        if (image_bgr is None) == (jpeg is None):
            raise ValueError("write_image needs exactly one of image_bgr ((H, W, 3) uint8 BGR array) or jpeg bytes")
        if image_bgr is not None:
            img = np.asarray(image_bgr)
            if img.dtype != np.uint8 or not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 3)):
                raise ValueError(f"image_bgr must be an (H, W, 3) uint8 BGR array, got shape {img.shape} "
                                 f"dtype {img.dtype}")
            if img.shape[0] == 0 or img.shape[1] == 0:
                raise ValueError(f"image_bgr is empty (shape {img.shape})")
            ok, buf = cv2.imencode(".jpg", img, [int(cv2.IMWRITE_JPEG_QUALITY), self.jpeg_quality])
            if not ok:
                raise ValueError(f"cv2.imencode failed to JPEG-encode an image of shape {img.shape}")
            data = buf.tobytes()
        else:
            data = bytes(jpeg)  # type: ignore[arg-type]
            if not data.startswith(b"\xff\xd8"):
                raise ValueError("jpeg must be JPEG-encoded bytes (starting with FF D8), "
                                 f"got {len(data)} bytes starting {data[:4]!r}")
        msg = CompressedImage(timestamp=_timestamp(t), frame_id=frame_id, data=data, format="jpeg")
        self.write_proto(topic, t, msg)

    def write_detections(self, topic: str, log_time_ns: int, detections: Sequence[Detection], *,
                         image_size: tuple[int, int] | None = None) -> None:
        """Write a ``foxglove.ImageAnnotations`` overlay for the image with the same timestamp.

        ``detections``: :class:`aerodaas.model.types.Detection` objects (or objects/dicts with ``box``, ``score``,
        ``class_name`` and optionally ``class_id``); ``box`` is pixel ``(x0, y0, x1, y1)``, origin top-left.
        Each detection becomes a closed ``LINE_LOOP`` points annotation through the 4 box corners (colour per
        class; metadata ``class_name``/``class_id``/``score``) and a ``TextAnnotation`` ``"<class_name> 0.87"``
        anchored at the box's top-left corner. ``image_size`` = ``(width, height)`` in pixels: when given, boxes
        are clipped to the image. An empty list writes an empty annotation message (clears the overlay).

        Raises ``ValueError`` for a malformed detection (box not 4 finite numbers) or a bad ``image_size``.
        """
        t = _check_time(log_time_ns)
        if image_size is not None:
            if len(image_size) != 2 or int(image_size[0]) <= 0 or int(image_size[1]) <= 0:
                raise ValueError(f"image_size must be (width, height) in pixels, got {image_size!r}")
            width, height = float(image_size[0]), float(image_size[1])
        stamp = _timestamp(t)
        ann = ImageAnnotations(timestamp=stamp)
        for det in detections:
            (x0, y0, x1, y1), score, class_name, class_id = _detection_fields(det)
            if image_size is not None:
                x0, x1 = min(max(x0, 0.0), width), min(max(x1, 0.0), width)
                y0, y1 = min(max(y0, 0.0), height), min(max(y1, 0.0), height)
            color = _class_color(class_name)
            meta = [KeyValuePair(key="class_name", value=class_name), KeyValuePair(key="score", value=f"{score:.4f}")]
            if class_id is not None:
                meta.append(KeyValuePair(key="class_id", value=str(class_id)))
            ann.points.append(PointsAnnotation(
                timestamp=stamp, type=PointsAnnotation.LINE_LOOP,
                points=[Point2(x=x0, y=y0), Point2(x=x1, y=y0), Point2(x=x1, y=y1), Point2(x=x0, y=y1)],
                outline_color=color, thickness=2.0, metadata=meta))
            ann.texts.append(TextAnnotation(
                timestamp=stamp, position=Point2(x=x0, y=y0), text=f"{class_name} {score:.2f}", font_size=14.0,
                text_color=Color(r=1.0, g=1.0, b=1.0, a=1.0),
                background_color=Color(r=color.r, g=color.g, b=color.b, a=0.6)))
        self.write_proto(topic, t, ann)

    def write_location(self, topic: str, log_time_ns: int, lat: float, lon: float, alt: float, *,
                       frame_id: str = "gps") -> None:
        """Write a ``foxglove.LocationFix``: WGS-84 ``lat``/``lon`` in degrees, ``alt`` in metres
        (``position_covariance_type`` UNKNOWN).

        Raises ``ValueError`` for non-finite values or lat outside [-90, 90] / lon outside [-180, 180].
        """
        t = _check_time(log_time_ns)
        lat_f, lon_f, alt_f = _finite("lat", lat), _finite("lon", lon), _finite("alt", alt)
        if not -90.0 <= lat_f <= 90.0:
            raise ValueError(f"lat must be within [-90, 90] degrees, got {lat_f}")
        if not -180.0 <= lon_f <= 180.0:
            raise ValueError(f"lon must be within [-180, 180] degrees, got {lon_f}")
        msg = LocationFix(timestamp=_timestamp(t), frame_id=frame_id, latitude=lat_f, longitude=lon_f,
                          altitude=alt_f, position_covariance=[0.0] * 9,
                          position_covariance_type=LocationFix.UNKNOWN)
        self.write_proto(topic, t, msg)

    def write_pose(self, topic: str, log_time_ns: int, position: Sequence[float], yaw_deg: float, *,
                   frame_id: str = "enu", roll_deg: float = 0.0, pitch_deg: float = 0.0) -> None:
        """Write a ``foxglove.PoseInFrame``: ``position`` ``(x, y, z)`` metres in ``frame_id`` (ENU by
        convention), orientation from roll/pitch/yaw **degrees** (ZYX, see :func:`quaternion_from_euler_deg`;
        yaw counter-clockwise from east).

        Raises ``ValueError`` for a position without 3 components or non-finite values.
        """
        t = _check_time(log_time_ns)
        x, y, z = _vec3("position", position)
        qx, qy, qz, qw = quaternion_from_euler_deg(roll_deg, pitch_deg, yaw_deg)
        msg = PoseInFrame(timestamp=_timestamp(t), frame_id=frame_id,
                          pose=Pose(position=Vector3(x=x, y=y, z=z),
                                    orientation=Quaternion(x=qx, y=qy, z=qz, w=qw)))
        self.write_proto(topic, t, msg)

    def write_transform(self, topic: str, log_time_ns: int, parent_frame: str, child_frame: str,
                        translation: Sequence[float], yaw_deg: float = 0.0, roll_deg: float = 0.0,
                        pitch_deg: float = 0.0, *, quaternion: Sequence[float] | None = None) -> None:
        """Write a ``foxglove.FrameTransform`` placing ``child_frame`` in ``parent_frame`` (typically on
        ``"/tf"``): ``translation`` ``(x, y, z)`` metres of the child origin in the parent frame, rotation from
        roll/pitch/yaw **degrees** (ZYX, see :func:`quaternion_from_euler_deg`), or ``quaternion`` ``(x, y, z, w)``
        (normalised here) instead of the angles.

        Raises ``ValueError`` for empty frame names, a translation without 3 components, a quaternion without 4
        components or of zero length, or non-finite values.
        """
        t = _check_time(log_time_ns)
        if not parent_frame or not child_frame:
            raise ValueError(f"parent_frame and child_frame must be non-empty, got {parent_frame!r}, {child_frame!r}")
        x, y, z = _vec3("translation", translation)
        if quaternion is None:
            qx, qy, qz, qw = quaternion_from_euler_deg(roll_deg, pitch_deg, yaw_deg)
        else:
            q = [_finite(f"quaternion[{i}]", c) for i, c in enumerate(quaternion)]
            n = math.sqrt(sum(c * c for c in q))
            if len(q) != 4 or n < 1e-12:
                raise ValueError(f"quaternion must be 4 finite components (x, y, z, w) of non-zero length, got {q}")
            qx, qy, qz, qw = (c / n for c in q)
        msg = FrameTransform(timestamp=_timestamp(t), parent_frame_id=parent_frame, child_frame_id=child_frame,
                             translation=Vector3(x=x, y=y, z=z), rotation=Quaternion(x=qx, y=qy, z=qz, w=qw))
        self.write_proto(topic, t, msg)

    def write_camera_calibration(self, topic: str, log_time_ns: int, *, width: int, height: int, fx: float,
                                 fy: float, cx: float, cy: float, frame_id: str) -> None:
        """Write a ``foxglove.CameraCalibration`` for an undistorted pinhole camera (Foxglove's convention, the
        ROS ``sensor_msgs/CameraInfo`` one): ``K = [fx 0 cx; 0 fy cy; 0 0 1]`` (pixels, row-major), ``R`` identity,
        ``P = [fx 0 cx 0; 0 fy cy 0; 0 0 1 0]``, ``D`` empty with ``distortion_model`` ``"plumb_bob"``; ``frame_id``
        names the camera's optical frame (z forward, x right, y down), the frame of its images.

        Raises ``ValueError`` for a non-positive width/height/focal length, non-finite values or an empty frame_id.
        """
        t = _check_time(log_time_ns)
        if int(width) <= 0 or int(height) <= 0:
            raise ValueError(f"width and height must be positive pixels, got {width!r} x {height!r}")
        fx_, fy_, cx_, cy_ = (_finite(n, v) for n, v in (("fx", fx), ("fy", fy), ("cx", cx), ("cy", cy)))
        if fx_ <= 0 or fy_ <= 0:
            raise ValueError(f"focal lengths fx, fy must be positive pixels, got {fx_}, {fy_}")
        if not frame_id:
            raise ValueError("write_camera_calibration needs the camera's frame_id")
        msg = CameraCalibration(timestamp=_timestamp(t), frame_id=frame_id, width=int(width), height=int(height),
                                distortion_model="plumb_bob", D=[],
                                K=[fx_, 0.0, cx_, 0.0, fy_, cy_, 0.0, 0.0, 1.0],
                                R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                                P=[fx_, 0.0, cx_, 0.0, 0.0, fy_, cy_, 0.0, 0.0, 0.0, 1.0, 0.0])
        self.write_proto(topic, t, msg)

    def write_json(self, topic: str, log_time_ns: int, obj: Mapping[str, Any], *, schema_name: str,
                   json_schema: dict | None = None) -> None:
        """Write ``obj`` as a JSON message (message encoding ``"json"``, schema encoding ``"jsonschema"``).

        ``obj`` is a dict (a pydantic model is accepted and dumped). numpy scalars/arrays become plain numbers/
        lists, NaN/inf become ``null``, other unknown objects ``str()``. ``schema_name`` names the schema (e.g.
        ``"aerodaas.MissionState"``); ``json_schema`` is the JSON Schema dict, default the one generated from the
        plug-in's schema of that name given to the constructor (``json_schemas``), else the one generated from the
        pydantic model registered for ``schema_name`` in :mod:`aerodaas.recording.schemas` (for a free-form schema
        such as ``aerodaas.AnalyticsOutput``, with the top-level fields of the topic's first message), else the
        permissive ``{"type": "object"}``. The schema is fixed by the first message on the topic.

        Raises ``TypeError`` if ``obj`` is not a mapping; ``ValueError`` for an empty ``schema_name`` or if the
        topic already carries another kind / another ``schema_name``.
        """
        t = _check_time(log_time_ns)
        if not schema_name:
            raise ValueError("write_json needs a non-empty schema_name")
        if hasattr(obj, "model_dump") and not isinstance(obj, Mapping):
            obj = obj.model_dump(mode="json")
        if not isinstance(obj, Mapping):
            raise TypeError(f"write_json expects a dict, got {type(obj).__name__}")
        plain = _jsonable(obj)
        data = json.dumps(plain, default=str, allow_nan=False, separators=(",", ":")).encode()
        if json_schema is None:  # generated once per topic (free-form outputs: from the topic's first message)
            schema_text = self._default_schema_text.get(topic)
            if schema_text is None:
                schema_text = json.dumps(self._plugin_schemas.get(schema_name) or json_schema_for(schema_name, plain)
                                         or _PERMISSIVE_SCHEMA, sort_keys=True)
                self._default_schema_text[topic] = schema_text
        else:
            schema_text = json.dumps(json_schema, sort_keys=True)

        def make_schema() -> tuple[str, str, bytes]:
            return schema_name, "jsonschema", schema_text.encode()

        self._write(topic, t, f"json:{schema_name}", make_schema, ("json", schema_name, schema_text), "json", data)

    # ---------------------------------------------------------------------------------------------------------
    def flush(self, *, fsync: bool = False) -> None:
        """Close the chunk in progress (if it has messages) and flush everything to the OS, so a crash after
        this loses nothing written so far. ``fsync=True`` also forces it to disk (survives a power loss).
        Each call ends a chunk, so calling it very often lowers compression. A no-op after :meth:`close`.
        """
        with self._lock:
            if self._closed:
                return
            self._writer.flush()  # finalizes the chunk and calls stream.flush()
            self._stream.flush()
            if fsync:
                os.fsync(self._file.fileno())

    def inject_write_fault(self, limit_bytes: int, code: int) -> None:
        """Fault injection (tests of the disk-failure path; never called in normal runs): from now on, a write
        that would take the file past ``limit_bytes`` bytes raises ``OSError(code)`` (e.g. ``errno.ENOSPC``), as
        a full or failing disk would."""
        with self._lock:
            self._stream.fail_writes_past(int(limit_bytes), int(code))

    def abandon(self) -> int:
        """The disk failed: close the file's descriptor without writing anything more (its pending buffer cannot
        be written) and stop taking messages. Returns the byte offset of the last record boundary the OS took (cut
        the file there for an unfinished but valid MCAP)."""
        with self._lock:
            durable = self._stream.durable
            try:
                self._file.close()
            except OSError:
                pass
            self._closed = True
            return durable

    def close(self) -> None:
        """Finish the file (last chunk, summary section with statistics/indexes, footer) and close it.
        Idempotent; writes afterwards raise ``RuntimeError``."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._writer.finish()
                self._stream.flush()
            finally:
                self._file.close()
