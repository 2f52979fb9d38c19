"""Frame-arrival processes for the scheduler benchmarks: periodic, realistic (jittered gaps, dropped frames, drones
joining and leaving mid-run), bursty (heavy-tailed gaps, on/off bursts, a link that stalls and flushes) and replayed
from a recording's camera-frame timestamps.

Real drone video is not periodic: encoders and links jitter each frame gap, frames are lost on the link, and drones
join and leave a fleet mid-mission. It also arrives in bursts: encoder GOPs and paused streams (on/off),
heavy-tailed gaps, and a link that stalls and then delivers its buffered frames back to back. Every bursty kind keeps
the mean frame rate (``1/period``), so a trace differs from the periodic one in its shape only.
:func:`frame_times` gives one drone's frame send times (ms) for a :class:`TraceSpec`; :func:`aerodaas.bench.workload.make_trace` turns them into the benchmark's task rows.

Every draw is seeded per (seed, drone) (:func:`random.Random` of a string, which CPython seeds through SHA-512), so a
drone's frames do not depend on the other drones nor on the fleet size.
"""
from __future__ import annotations

import functools
import math
import random
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from aerodaas.recording.reader import _iter_raw, _open_mcap

__all__ = ["TraceSpec", "TRACE_KINDS", "frame_times", "recording_frame_gaps", "gap_stats", "IMAGE_SCHEMAS"]

TRACE_KINDS = ("periodic", "realistic", "recording", "pareto", "onoff", "flush")
#: the parameters each kind uses (any other given is refused: an option that would be silently ignored)
KIND_PARAMS = {"periodic": (), "realistic": ("jitter", "drop", "joins", "leaves"),
               "recording": ("drop", "joins", "leaves"), "pareto": ("alpha", "drop", "joins", "leaves"),
               "onoff": ("on_s", "off_s", "drop", "joins", "leaves"),
               "flush": ("stall_s", "stall_every_s", "flush_gap_ms", "drop", "joins", "leaves")}
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
    - ``"pareto"``: i.i.d. Pareto gaps of shape ``alpha`` (> 1; 1.5: infinite variance) and scale ``period x (alpha
      - 1) / alpha`` (mean gap = period; :meth:`random.Random.paretovariate`).
    - ``"onoff"``: each drone alternates ``on_s`` s of frames at ``(on_s + off_s) / on_s`` x the rate and ``off_s`` s
      of silence, from a seeded phase of the cycle (an encoder's bursts, a stream that pauses).
    - ``"flush"``: frames are made every period, but the link stalls — up for an exponential time of mean
      ``stall_every_s`` s, then down for an exponential time of mean ``stall_s`` s; frames made while it is down
      arrive when it comes back, ``flush_gap_ms`` ms apart (a buffer flushed).
    ``drop``, ``joins`` and ``leaves`` apply to the bursty kinds as to ``"realistic"`` (default 0).

    Raises ValueError (naming the field and value) for a bad kind, a jitter outside [0, 1), a drop outside [0, 1),
    negative joins/leaves, ``recording`` missing for kind ``"recording"``, ``alpha`` <= 1, non-positive on/off,
    stall or flush times.
    """

    kind: str = "periodic"
    jitter: float = 0.0
    drop: float = 0.0
    joins: int = 0
    leaves: int = 0
    recording: str | None = None
    alpha: float = 1.5
    on_s: float = 3.0
    off_s: float = 3.0
    stall_s: float = 2.0
    stall_every_s: float = 6.0
    flush_gap_ms: float = 2.0

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
        if not (self.alpha > 1 and math.isfinite(self.alpha)):
            raise ValueError(f"trace alpha: a Pareto shape > 1 needed (a finite mean gap), got {self.alpha}")
        for name in ("on_s", "off_s", "stall_s", "stall_every_s", "flush_gap_ms"):
            v = getattr(self, name)
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"trace {name}: a finite number > 0 needed, got {v}")

    @classmethod
    def parse(cls, text: str, **given: float | int | None) -> "TraceSpec":
        """``"periodic"``, ``"realistic"``, ``"pareto"``, ``"onoff"``, ``"flush"`` or ``"recording:PATH"`` plus
        optional parameters (``jitter``, ``drop``, ``joins``, ``leaves``, ``alpha``, ``on_s``, ``off_s``,
        ``stall_s``, ``stall_every_s``, ``flush_gap_ms``; None: the kind's default). Raises ValueError as the
        constructor, for a missing recording file, and for a parameter the kind does not use (it would be
        silently ignored)."""
        kind, _, path = text.partition(":")
        if kind == "recording" and not Path(path).is_file():
            raise ValueError(f"trace recording: no file {path!r}")
        if kind not in KIND_PARAMS:
            raise ValueError(f"trace kind: choose from {list(TRACE_KINDS)}, got {kind!r}")
        unknown = sorted(set(given) - set(_DEFAULTS))
        if unknown:
            raise ValueError(f"trace parameters: unknown {unknown}; known {sorted(_DEFAULTS)}")
        unused = {k: v for k, v in given.items() if v is not None and k not in KIND_PARAMS[kind]}
        if unused:
            hint = "; use 'realistic'" if kind == "periodic" else ""
            raise ValueError(f"trace {kind} takes no {'/'.join(unused)} (got {unused}): it uses "
                             f"{list(KIND_PARAMS[kind]) or 'no parameter'}{hint}")
        vals = {k: given.get(k) if given.get(k) is not None else _DEFAULTS[k].get(kind, _DEFAULTS[k]["*"])
                for k in _DEFAULTS}
        return cls(kind, recording=path if kind == "recording" else None, **vals)

    def label(self) -> str:
        """Short description for reports, e.g. ``realistic(jitter 0.2, drop 0.1, joins 1, leaves 0)``."""
        if self.kind == "periodic":
            return "periodic"
        shape = {"recording": f"recording {Path(self.recording or '').name}, ",
                 "realistic": f"jitter {self.jitter:g}, ",
                 "pareto": f"alpha {self.alpha:g}, ", "onoff": f"on {self.on_s:g} s, off {self.off_s:g} s, ",
                 "flush": f"stall {self.stall_s:g} s every {self.stall_every_s:g} s, flushed "
                          f"{self.flush_gap_ms:g} ms apart, "}[self.kind]
        return f"{self.kind}({shape}drop {self.drop:g}, joins {self.joins}, leaves {self.leaves})"


#: per parameter, its default by kind ("*": every other kind); a recording's own losses are already in its gaps
_DEFAULTS = {"jitter": {"realistic": 0.2, "*": 0.0}, "drop": {"realistic": 0.1, "*": 0.0},
             "joins": {"realistic": 1, "*": 0}, "leaves": {"*": 0}, "alpha": {"*": 1.5}, "on_s": {"*": 3.0},
             "off_s": {"*": 3.0}, "stall_s": {"*": 2.0}, "stall_every_s": {"*": 6.0}, "flush_gap_ms": {"*": 2.0}}

def recording_frame_gaps(path: str | Path) -> list[list[float]]:
    """Per camera topic of the MCAP recording ``path`` (messages of :data:`IMAGE_SCHEMAS`, in log-time order): the
    gaps between consecutive frames' log times, in ms. Topics with fewer than 3 frames are skipped. Read once per
    resolved path in a process (:func:`_frame_gaps`). Raises FileNotFoundError, ValueError (not an MCAP file, or no
    camera topic with 3 frames)."""
    return _frame_gaps(str(Path(path).resolve()))


@functools.cache
def _frame_gaps(path: str) -> list[list[float]]:
    """:func:`recording_frame_gaps` of the resolved ``path``, memoised by ``functools.cache`` (a failed read raises
    and is not remembered)."""
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
    return out


def frame_times(spec: TraceSpec, drone: str, index_on_edge: int, drones_on_edge: int, index_in_fleet: int,
                period_ms: float, duration_ms: float, seed: int) -> list[float]:
    """Send times (ms, rounded to µs, increasing, in [0, ``duration_ms``)) of ``drone``'s frames under ``spec``
    (not ``"periodic"``, which :func:`aerodaas.bench.workload.make_trace` generates itself to keep the published
    sweep's traces). ``index_on_edge`` / ``drones_on_edge`` decide who joins (the last ``joins``) and who leaves
    (the first ``leaves``); ``index_in_fleet`` picks the recording stream."""
    rng = random.Random(f"aerodaas-trace/{seed}/{drone}")
    start, end = 0.0, duration_ms
    if index_on_edge >= drones_on_edge - spec.joins:
        start = rng.uniform(0.2, 0.5) * duration_ms
    if index_on_edge < spec.leaves:
        end = rng.uniform(0.5, 0.8) * duration_ms
    if spec.kind in ("onoff", "flush"):
        times = (_onoff_times if spec.kind == "onoff" else _flush_times)(spec, rng, start, end, period_ms)
        return [round(t, 3) for t in times if not rng.random() < spec.drop]
    gap = _gap_process(spec, rng, index_in_fleet, period_ms)
    t = start + rng.uniform(0.0, period_ms)
    out = []
    while t < end:  # the loss draw before each gap draw: the published realistic traces' order of draws
        if not rng.random() < spec.drop:
            out.append(round(t, 3))
        t += gap()
    return out


def _gap_process(spec: TraceSpec, rng: random.Random, index_in_fleet: int, period_ms: float):
    """The next-gap function (ms) of the kinds made of i.i.d. or replayed gaps."""
    if spec.kind == "recording":
        streams = recording_frame_gaps(spec.recording)
        gaps = streams[index_in_fleet % len(streams)]
        scale = period_ms / (sum(gaps) / len(gaps))
        k = rng.randrange(len(gaps))

        def gap() -> float:
            nonlocal k
            k = (k + 1) % len(gaps)
            return max(gaps[k] * scale, 1e-3)
        return gap
    if spec.kind == "pareto":
        xm = period_ms * (spec.alpha - 1.0) / spec.alpha
        return lambda: xm * rng.paretovariate(spec.alpha)
    return lambda: period_ms * (1.0 + rng.uniform(-spec.jitter, spec.jitter))


def _onoff_times(spec: TraceSpec, rng: random.Random, start: float, end: float, period_ms: float) -> list[float]:
    """Frames every ``period x on / (on + off)`` ms while on, none while off, from a seeded phase of the cycle."""
    on, cycle = spec.on_s * 1000.0, (spec.on_s + spec.off_s) * 1000.0
    gap = period_ms * on / cycle
    t0 = start - rng.uniform(0.0, cycle)          # the cycle began this long before the drone's start
    out = []
    k = 0
    while True:
        c = t0 + k * cycle
        if c >= end:
            return out
        t = c
        while t < c + on and t < end:
            if t >= start:
                out.append(t)
            t += gap
        k += 1


def _flush_times(spec: TraceSpec, rng: random.Random, start: float, end: float, period_ms: float) -> list[float]:
    """Frames made every period; the link alternates up (exponential, mean ``stall_every_s``) and down
    (exponential, mean ``stall_s``); a frame made while it is down arrives when it is back up, the buffered frames
    ``flush_gap_ms`` apart, never before an earlier frame."""
    up = start + rng.expovariate(1.0 / (spec.stall_every_s * 1000.0)) * rng.random()  # a seeded point of the cycle
    down = up + rng.expovariate(1.0 / (spec.stall_s * 1000.0))
    out: list[float] = []
    t = start + rng.uniform(0.0, period_ms)
    while t < end:
        while t >= down:                               # the link's next stall
            up = down + rng.expovariate(1.0 / (spec.stall_every_s * 1000.0))
            down = up + rng.expovariate(1.0 / (spec.stall_s * 1000.0))
        at = down if t >= up else t                    # made during a stall: delivered when it ends
        if out:                                        # behind the frames still being flushed
            at = max(at, out[-1] + spec.flush_gap_ms)
        if at >= end:
            break
        out.append(at)
        t += period_ms
    return out


def gap_stats(times: Sequence[float]) -> dict:
    """Mean, min, max and coefficient of variation of the gaps between consecutive ``times`` (ms)."""
    gaps = [b - a for a, b in zip(times, times[1:])]
    if not gaps:
        return {"n": 0}
    m = sum(gaps) / len(gaps)
    sd = math.sqrt(sum((g - m) ** 2 for g in gaps) / len(gaps))
    return {"n": len(gaps), "mean": m, "min": min(gaps), "max": max(gaps), "cv": sd / m if m else math.nan}
