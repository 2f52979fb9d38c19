"""Frame-arrival processes for the scheduler benchmarks: periodic, realistic (jittered gaps, dropped frames, drones
joining and leaving mid-run) and replayed from a recording's camera-frame timestamps.

Real drone video is not periodic: encoders and links jitter each frame gap, frames are lost on the link, and drones
join and leave a fleet mid-mission. :func:`frame_times` gives one drone's frame send times (ms) for a
:class:`TraceSpec`; :func:`aerodaas.bench.schedulers.make_trace` turns them into the benchmark's task rows.

Every draw is seeded per (seed, drone) (:func:`random.Random` of a string, which CPython seeds through SHA-512), so a
drone's frames do not depend on the other drones nor on the fleet size.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

__all__ = ["TraceSpec", "TRACE_KINDS", "frame_times", "recording_frame_gaps", "gap_stats", "IMAGE_SCHEMAS"]

TRACE_KINDS = ("periodic", "realistic", "recording")
#: MCAP schemas whose messages are camera frames (foxglove.CompressedImage / RawImage, as the recorder writes them)
IMAGE_SCHEMAS = ("foxglove.CompressedImage", "foxglove.RawImage")


@dataclass(frozen=True)
class TraceSpec:
    """How drones send frames.

    - ``kind`` ``"periodic"``: a frame every ``1/fps`` s from a seeded phase (the published sweep's trace).
    - ``"realistic"``: each gap is ``1/fps`` x (1 + U(-``jitter``, +``jitter``)); each frame is lost with
      probability ``drop``; on each edge the last ``joins`` drones join at a seeded time in [0.2, 0.5] x the run and
      the first ``leaves`` drones leave at a seeded time in [0.5, 0.8] x the run.
    - ``"recording"``: the inter-frame gaps of the camera topics of the MCAP file ``recording`` (one stream per
      camera topic; fleet drone *i* replays stream *i* mod *n* from a seeded gap index, looping), scaled so the mean
      gap is ``1/fps`` s (the real gap *shape* at the benchmark's rate), with ``drop``, ``joins`` and ``leaves`` as
      above (defaults 0 for a recording: its own losses are already in its gaps).

    Raises ValueError (naming the field and value) for a bad kind, a jitter outside [0, 1), a drop outside [0, 1),
    negative joins/leaves, or ``recording`` missing for kind ``"recording"``.
    """

    kind: str = "periodic"
    jitter: float = 0.0
    drop: float = 0.0
    joins: int = 0
    leaves: int = 0
    recording: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in TRACE_KINDS:
            raise ValueError(f"trace kind: choose from {list(TRACE_KINDS)}, got {self.kind!r}")
        if not (0.0 <= self.jitter < 1.0):
            raise ValueError(f"trace jitter: a fraction of the frame gap in [0, 1) needed, got {self.jitter}")
        if not (0.0 <= self.drop < 1.0):
            raise ValueError(f"trace drop: a probability in [0, 1) needed, got {self.drop}")
        if self.joins < 0 or self.leaves < 0:
            raise ValueError(f"trace joins/leaves: integers >= 0 needed, got {self.joins}/{self.leaves}")
        if self.kind == "recording" and not self.recording:
            raise ValueError("trace recording: a recording's path is needed for kind 'recording'")

    @classmethod
    def parse(cls, text: str, *, jitter: float | None = None, drop: float | None = None, joins: int | None = None,
              leaves: int | None = None) -> "TraceSpec":
        """``"periodic"``, ``"realistic"`` or ``"recording:PATH"`` plus optional overrides (None: the kind's
        default). Raises ValueError as the constructor, and for a missing recording file."""
        kind, _, path = text.partition(":")
        if kind == "recording" and not Path(path).is_file():
            raise ValueError(f"trace recording: no file {path!r}")
        given = {"jitter": jitter, "drop": drop, "joins": joins, "leaves": leaves}
        if kind == "periodic" and any(v for v in given.values()):
            raise ValueError(f"trace periodic takes no jitter/drop/joins/leaves (got {given}); use 'realistic'")
        base = _DEFAULTS.get(kind)
        if base is None:
            raise ValueError(f"trace kind: choose from {list(TRACE_KINDS)}, got {kind!r}")
        vals = {k: base[k] if v is None else v for k, v in given.items()}
        return cls(kind, recording=path if kind == "recording" else None, **vals)

    def label(self) -> str:
        """Short description for reports, e.g. ``realistic(jitter 0.2, drop 0.1, joins 1, leaves 0)``."""
        if self.kind == "periodic":
            return "periodic"
        src = f"recording {Path(self.recording).name}, " if self.recording else f"jitter {self.jitter:g}, "
        return f"{self.kind}({src}drop {self.drop:g}, joins {self.joins}, leaves {self.leaves})"


#: per kind, the defaults of jitter, drop, joins and leaves (a recording's own losses are already in its gaps)
_DEFAULTS = {"periodic": dict(jitter=0.0, drop=0.0, joins=0, leaves=0),
             "realistic": dict(jitter=0.2, drop=0.1, joins=1, leaves=0),
             "recording": dict(jitter=0.0, drop=0.0, joins=0, leaves=0)}

_GAP_CACHE: dict[str, list[list[float]]] = {}


def recording_frame_gaps(path: str | Path) -> list[list[float]]:
    """Per camera topic of the MCAP recording ``path`` (messages of :data:`IMAGE_SCHEMAS`, in log-time order): the
    gaps between consecutive frames' log times, in ms. Topics with fewer than 3 frames are skipped. Raises
    FileNotFoundError, ValueError (not an MCAP file, or no camera topic with 3 frames)."""
    from aerodaas.recording.reader import _iter_raw, _open_mcap

    key = str(Path(path).resolve())
    if key in _GAP_CACHE:
        return _GAP_CACHE[key]
    times: dict[str, list[int]] = {}
    f, finished = _open_mcap(path)
    with f:
        for schema, channel, message in _iter_raw(f, None, finished):
            if schema is not None and schema.name in IMAGE_SCHEMAS:
                times.setdefault(channel.topic, []).append(message.log_time)
    out = []
    for topic in sorted(times):
        ts = sorted(times[topic])
        if len(ts) >= 3:
            out.append([(b - a) / 1e6 for a, b in zip(ts, ts[1:])])
    if not out:
        raise ValueError(f"trace recording {path}: no camera topic ({', '.join(IMAGE_SCHEMAS)}) with >= 3 frames")
    _GAP_CACHE[key] = out
    return out


def frame_times(spec: TraceSpec, drone: str, index_on_edge: int, drones_on_edge: int, index_in_fleet: int,
                period_ms: float, duration_ms: float, seed: int) -> list[float]:
    """Send times (ms, rounded to µs, increasing, in [0, ``duration_ms``)) of ``drone``'s frames under ``spec``
    (not ``"periodic"``, which :func:`aerodaas.bench.schedulers.make_trace` generates itself to keep the published
    sweep's traces). ``index_on_edge`` / ``drones_on_edge`` decide who joins (the last ``joins``) and who leaves
    (the first ``leaves``); ``index_in_fleet`` picks the recording stream."""
    rng = random.Random(f"aerodaas-trace/{seed}/{drone}")
    start, end = 0.0, duration_ms
    if index_on_edge >= drones_on_edge - spec.joins:
        start = rng.uniform(0.2, 0.5) * duration_ms
    if index_on_edge < spec.leaves:
        end = rng.uniform(0.5, 0.8) * duration_ms
    if spec.kind == "recording":
        streams = recording_frame_gaps(spec.recording)
        gaps = streams[index_in_fleet % len(streams)]
        scale = period_ms / (sum(gaps) / len(gaps))
        k = rng.randrange(len(gaps))

        def gap() -> float:
            nonlocal k
            k = (k + 1) % len(gaps)
            return max(gaps[k] * scale, 1e-3)
    else:
        def gap() -> float:
            return period_ms * (1.0 + rng.uniform(-spec.jitter, spec.jitter))
    t = start + rng.uniform(0.0, period_ms)
    out = []
    while t < end:
        if not rng.random() < spec.drop:
            out.append(round(t, 3))
        t += gap()
    return out


def gap_stats(times: Sequence[float]) -> dict:
    """Mean, min, max and coefficient of variation of the gaps between consecutive ``times`` (ms)."""
    gaps = [b - a for a, b in zip(times, times[1:])]
    if not gaps:
        return {"n": 0}
    m = sum(gaps) / len(gaps)
    sd = math.sqrt(sum((g - m) ** 2 for g in gaps) / len(gaps))
    return {"n": len(gaps), "mean": m, "min": min(gaps), "max": max(gaps), "cv": sd / m if m else math.nan}
