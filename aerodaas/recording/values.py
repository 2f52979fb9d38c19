"""Values as the recording writes them: rotations (quaternions from Euler angles in degrees, a camera mount's
optical frame), protobuf timestamps from nanoseconds, checked finite numbers and 3-vectors, JSON-safe conversion
of models and arrays, a detection's box/score/label and its stable colour. Used by :mod:`aerodaas.recording.writer`."""
from __future__ import annotations

import enum
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from foxglove_schemas_protobuf.Color_pb2 import Color
from google.protobuf.timestamp_pb2 import Timestamp


# --------------------------------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------------------------------
def quaternion_from_euler_deg(roll_deg: float = 0.0, pitch_deg: float = 0.0,
                              yaw_deg: float = 0.0) -> tuple[float, float, float, float]:
    """Unit quaternion ``(x, y, z, w)`` for roll/pitch/yaw in **degrees**, ZYX convention.

    The rotation is yaw about +Z (up, so positive yaw turns counter-clockwise seen from above, i.e. from east
    towards north in ENU), then pitch about the new +Y, then roll about the newest +X (intrinsic Z-Y'-X'', the
    aerospace/ROS ``RPY`` convention): ``q = q_z(yaw) * q_y(pitch) * q_x(roll)``.
    Example: ``yaw_deg=90`` gives ``(0, 0, sin 45°, cos 45°)``.

    Raises ``ValueError`` if an angle is not finite.
    """
    for name, v in (("roll_deg", roll_deg), ("pitch_deg", pitch_deg), ("yaw_deg", yaw_deg)):
        if not math.isfinite(float(v)):
            raise ValueError(f"{name} must be a finite number of degrees, got {v!r}")
    hr, hp, hy = (math.radians(float(a)) / 2.0 for a in (roll_deg, pitch_deg, yaw_deg))
    cr, sr = math.cos(hr), math.sin(hr)
    cp, sp = math.cos(hp), math.sin(hp)
    cy, sy = math.cos(hy), math.sin(hy)
    w = cr * cp * cy + sr * sp * sy
    x = sr * cp * cy - cr * sp * sy
    y = cr * sp * cy + sr * cp * sy
    z = cr * cp * sy - sr * sp * cy
    return (x, y, z, w)


def _quat_mul(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    """Hamilton product ``a * b`` of ``(x, y, z, w)`` quaternions (rotation ``b`` first, then ``a``)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def camera_mount_quaternion(pitch_deg: float) -> tuple[float, float, float, float]:
    """Rotation ``(x, y, z, w)`` of a camera's **optical** frame (z along the optical axis, x right, y down: the
    frame of Foxglove's ``CameraCalibration`` and OpenCV) in the body frame ``base_link`` (x forward, y left,
    z up; ENU-aligned at yaw 0), for a camera looking forward and pitched ``pitch_deg`` below the horizon
    (90 = nadir, the top of the image then points forward).

    It is the ROS optical-frame rotation ``rpy = (-90°, 0, -90°)`` (REP 103) followed by a pitch of ``pitch_deg``
    about the body's +y axis (positive pitch tilts the nose down in a z-up frame). Matches the simulator's
    camera (:func:`aerodaas.model.camera.camera_rotation`). Raises ``ValueError`` for a non-finite angle."""
    optical = quaternion_from_euler_deg(-90.0, 0.0, -90.0)
    return _quat_mul(quaternion_from_euler_deg(0.0, pitch_deg, 0.0), optical)


def _timestamp(ns: int) -> Timestamp:
    return Timestamp(seconds=ns // 1_000_000_000, nanos=ns % 1_000_000_000)


def _check_time(log_time_ns: Any) -> int:
    if isinstance(log_time_ns, bool) or not isinstance(log_time_ns, (int, np.integer)):
        raise TypeError(f"log_time_ns must be an int of nanoseconds, got {type(log_time_ns).__name__} {log_time_ns!r}")
    t = int(log_time_ns)
    if not 0 <= t < 2**64:
        raise ValueError(f"log_time_ns must be within [0, 2**64) nanoseconds, got {t}")
    return t


def _finite(name: str, v: Any) -> float:
    f = float(v)
    if not math.isfinite(f):
        raise ValueError(f"{name} must be finite, got {v!r}")
    return f


def _vec3(name: str, v: Sequence[float]) -> tuple[float, float, float]:
    vals = tuple(v)
    if len(vals) != 3:
        raise ValueError(f"{name} must have 3 components (x, y, z) in metres, got {len(vals)}")
    return tuple(_finite(f"{name}[{i}]", c) for i, c in enumerate(vals))  # type: ignore[return-value]


def _jsonable(o: Any) -> Any:
    """Recursively convert ``o`` to plain JSON types: numpy scalars/arrays to Python numbers/lists, NaN/inf to
    ``None`` (JSON has no NaN), tuples/sets to lists, enums to their value, pydantic models to dicts, dict keys
    to ``str``. Anything else unknown is left for ``json.dumps(default=str)``."""
    if o is None or isinstance(o, (str, bool, int)):
        return o
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, np.generic):
        return _jsonable(o.item())
    if isinstance(o, np.ndarray):
        return _jsonable(o.tolist())
    if isinstance(o, enum.Enum):
        return _jsonable(o.value)
    if isinstance(o, Mapping):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple, set, frozenset)):
        return [_jsonable(v) for v in o]
    if hasattr(o, "model_dump"):  # pydantic v2 model
        return _jsonable(o.model_dump(mode="json"))
    if isinstance(o, (bytes, bytearray)):
        return o.hex()
    return o


def _detection_fields(det: Any) -> tuple[tuple[float, float, float, float], float, str, int | None]:
    """(box, score, class_name, class_id) from a :class:`~aerodaas.model.types.Detection`-like object or dict."""
    get = det.get if isinstance(det, Mapping) else (lambda k, d=None: getattr(det, k, d))
    box = get("box")
    if box is None or len(box) != 4:
        raise ValueError(f"detection needs a 4-element pixel box (x0, y0, x1, y1), got {box!r}")
    x0, y0, x1, y1 = (_finite("detection box", c) for c in box)
    score = _finite("detection score", get("score", 0.0))
    class_id = get("class_id")
    return (min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1)), score, str(get("class_name", "")), class_id


def _class_color(name: str) -> Color:
    """Deterministic, fairly saturated colour for a class name (same class, same colour in every file)."""
    h = 0
    for ch in name.encode():
        h = (h * 131 + ch) & 0xFFFFFFFF
    hue = (h % 360) / 60.0
    c, x = 0.9, 0.9 * (1 - abs(hue % 2 - 1))
    r, g, b = [(c, x, 0), (x, c, 0), (0, c, x), (0, x, c), (x, 0, c), (c, 0, x)][int(hue) % 6]
    return Color(r=r + 0.1, g=g + 0.1, b=b + 0.1, a=1.0)
