"""``aerodaas bench recorder``: the ceiling of the run's one recorder actor.

A run records through one :class:`~aerodaas.actors.recording.actor.RecorderActor`: every other actor's
:class:`~aerodaas.actors.recording.remote_recorder.RemoteRecorder` batches its messages to it (every 0.1 s, frames as JPEG
bytes) and its :class:`~aerodaas.actors.recording.recorder.RecorderService` writes them into one MCAP. This benchmark drives
that same path with synthetic drones and measures what reaches the file:

* each simulated drone offers a camera frame ``--fps`` times a second (a real aerial photo,
  ``$AERODAAS_DATA_DIR/imagery/caliterra/IMG_9354.jpg``, resized to ``--width`` x ``--height`` and JPEG-encoded at
  quality 80: 16 distinct windows of it, about 100 KB each at 1280x720; textured synthetic frames without the data
  dir) and
  an odometry sample ``--odom-hz`` times a second (written as GPS fix, pose, three transforms and the odometry
  JSON); the drones are spread over ``--producers`` producer actors (as ``drones_per_actor`` packs them), each
  pacing its drones to the wall clock;
* per fleet size (``--drones``, repeatable): messages and MB recorded per second of the whole run (offering plus
  the drain after the last offer), the frames the recorder refused (its queue of frames to write is bounded, 64),
  the messages lost by the recording's own accounting (:func:`aerodaas.recording.accounting.account_recording`:
  produced - recorded), the producers' lag behind their schedule and the drain time (how long the recorder needed
  after the last message was offered: the back-pressure);
* side by side, the bare baseline: the same messages (read back from that run's file) written with the ``mcap``
  library directly in one process, zstd chunks of 256 KiB as the recorder writes them.

With ``--recorders R`` the producers are spread over R recorder actors, each writing its own file with its own
accounting, as ``recording.per_node: true`` gives a run one recorder per node (the files' counts are summed per
row): on one machine this measures what a second recorder process adds; on a cluster each node adds one.

The report's ``limit`` names the first fleet size that lost messages or drained for longer than one second, and the
``ceiling`` is the largest recorded throughput of a size without loss. Nothing is written outside a temporary
folder (removed at the end).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import ray
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from aerodaas.actors.recording.actor import RecorderActor
from aerodaas.actors.recording.remote_recorder import RemoteRecorder
from aerodaas.bench.machine import machine_info
from aerodaas.bench.output import emit_report, print_report
from aerodaas.bench.progress import bench_progress
from aerodaas.protocol.specs import ActorSpec, RecordSpec
from aerodaas.recording.accounting import account_recording
from aerodaas.recording.reader import summarize_mcap
from aerodaas.runtime import ray_start

DEFAULT_SIZES = (5, 10, 20, 40, 80)
#: a drain longer than this (seconds after the last offer until the file is finished) counts as back-pressure
DRAIN_LIMIT_S = 1.0
PHOTO = Path("imagery") / "caliterra" / "IMG_9354.jpg"


@dataclass(frozen=True)
class DroneLoad:
    """What each simulated drone offers: ``fps`` JPEG frames/s (cycling through ``frames``, JPEG bytes) and
    ``odom_hz`` odometry samples/s, for ``duration_s`` seconds of wall clock."""

    fps: float
    odom_hz: float
    duration_s: float
    frames: list[bytes]
    width: int
    height: int


def bench_frames(width: int, height: int, count: int = 16, quality: int = 80) -> tuple[list[bytes], str]:
    """``count`` distinct realistic camera frames as JPEG bytes and where they came from: windows of the shared
    aerial photo (``$AERODAAS_DATA_DIR/``:data:`PHOTO`, 4000x3000) at different offsets, resized to ``width`` x
    ``height`` pixels, else synthetic textured frames (field pattern plus noise, compressing to a similar size).
    Distinct, so that the recorder's zstd chunks cannot shrink a repeated frame (a chunk of 256 KiB holds two or
    three). Raises ValueError for a size below 16 px or ``count`` < 1."""
    import cv2  # lazy: heavy dependency (OpenCV)

    if width < 16 or height < 16 or count < 1:
        raise ValueError(f"frame size must be at least 16x16 pixels and count >= 1, got {width}x{height}, {count}")
    photo = Path(os.environ.get("AERODAAS_DATA_DIR", "")) / PHOTO
    img = cv2.imread(str(photo)) if photo.is_file() else None
    source = str(photo) if img is not None else "synthetic"
    if img is None:
        rng = np.random.default_rng(0)
        yy, xx = np.mgrid[0:2 * height, 0:2 * width]
        base = 110 + 60 * np.sin(xx / 23.0) * np.cos(yy / 31.0)
        img = np.clip(base[..., None] + rng.normal(0, 18, (2 * height, 2 * width, 3)), 0, 255).astype(np.uint8)
    h, w = img.shape[:2]
    wh, ww = int(h * 0.75), int(w * 0.75)  # windows of 3/4 of the photo, stepping across it
    out = []
    for i in range(count):
        y0 = (h - wh) * (i % 4) // 3
        x0 = (w - ww) * ((i // 4) % 4) // 3 + i  # + i: distinct even past 16 windows
        win = img[y0:y0 + wh, min(x0, w - ww):min(x0, w - ww) + ww]
        ok, buf = cv2.imencode(".jpg", cv2.resize(win, (width, height), interpolation=cv2.INTER_AREA),
                               [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        if not ok:  # pragma: no cover - OpenCV encodes any uint8 BGR image
            raise RuntimeError("OpenCV could not JPEG-encode a benchmark frame")
        out.append(buf.tobytes())
    return out, source


def odometry_sample(robot_index: int, t_s: float) -> dict:
    """One odometry dict as a drone actor records it (``position`` ENU m, ``attitude`` deg, ``geodetic`` WGS-84
    deg / m, ``velocity`` m/s, ``battery`` %), for drone ``robot_index`` at ``t_s`` seconds of flight."""
    x, y = 3.0 * math.cos(t_s / 5.0) + robot_index * 8.0, 3.0 * math.sin(t_s / 5.0)
    return {"position": [x, y, 20.0], "velocity": [0.6, 0.6, 0.0],
            "attitude": {"roll": 0.5, "pitch": -1.0, "yaw": (t_s * 7.0) % 360.0},
            "geodetic": {"lat": -35.363 + y * 9e-6, "lon": 149.165 + x * 1.1e-5, "alt": 604.0},
            "battery": 100.0 - t_s * 0.05, "t": t_s}


class _BenchPlane:
    """The part of a :class:`~aerodaas.actors.data.plane.DataPlane` a RemoteRecorder uses: this actor's id and its
    peers (here only the recorder actor)."""

    def __init__(self, actor_id: str, recorder: Any) -> None:
        self.actor_id = actor_id
        self._recorder = recorder
        self.copies = None

    def peer(self, name: str) -> Any:
        """The recorder actor's handle (the only peer of a benchmark producer). Raises KeyError for another."""
        if name != "recorder":
            raise KeyError(f"bench producer has no peer {name!r}")
        return self._recorder


class BenchProducer:
    """A producer actor of the benchmark (made a Ray actor by :func:`_producer_class`): offers its drones' frames
    and odometry through a real :class:`~aerodaas.actors.recording.remote_recorder.RemoteRecorder` to the recorder actor."""

    def __init__(self, actor_id: str, recorder: Any) -> None:
        self.rec = RemoteRecorder(_BenchPlane(actor_id, recorder))

    def ready(self) -> bool:
        """True once the actor is up (the driver waits for every producer before it sets the start time)."""
        return True

    def run(self, robots: list[int], load: DroneLoad, epoch_ns: int, start_at: float) -> dict:
        """Offer ``load`` for each drone in ``robots`` from wall time ``start_at`` on, paced to the wall clock
        (a producer behind its schedule offers at once, never skips); then deliver the rest and wait for the
        recorder to take it. Returns ``{"offered", "frames_dropped", "max_lag_s", "send_errors", "started",
        "last_offer"}`` (wall times, s since the epoch, of its first and last offer)."""
        intr = {"width": load.width, "height": load.height, "fx": load.width * 0.8, "fy": load.width * 0.8,
                "cx": load.width / 2, "cy": load.height / 2}
        for r in robots:
            self.rec.camera(f"d{r}", "cam", intr, 90.0)
        events = sorted([(k / load.fps, 0, r) for r in robots for k in range(int(load.duration_s * load.fps))]
                        + [(k / load.odom_hz, 1, r) for r in robots for k in range(int(load.duration_s * load.odom_hz))])
        time.sleep(max(0.0, start_at - time.time()))
        t0, started, offered, lag = time.monotonic(), time.time(), 0, 0.0
        for i, (at, kind, r) in enumerate(events):
            wait = at - (time.monotonic() - t0)
            if wait > 0:
                time.sleep(wait)
            else:
                lag = max(lag, -wait)
            t_ns = epoch_ns + int(at * 1e9)
            if kind == 0:
                self.rec.image(f"/d{r}/camera/cam", t_ns, load.frames[(i + r) % len(load.frames)], f"d{r}/cam")
            else:
                self.rec.odometry(f"d{r}", t_ns, odometry_sample(r, at))
            offered += 1
        last = time.time()
        self.rec.close(timeout_s=120.0)
        return {"offered": offered, "frames_dropped": self.rec.frames_dropped, "max_lag_s": round(lag, 3),
                "send_errors": self.rec.send_errors[-3:], "started": started,
                "last_offer": last}


def _producer_class() -> Any:
    return ray.remote(num_cpus=0)(BenchProducer)


def run_size(n: int, load: DroneLoad, producers: int, folder: Path, recorders: int = 1) -> dict:
    """One fleet size ``n`` on the running Ray: ``recorders`` fresh recorder actors (as ``recording.per_node``
    makes one per node: each writes ``folder/run-<n>-<j>.mcap`` with its own accounting) and ``producers`` producer
    actors (at least one per recorder; producer i sends to recorder i mod ``recorders``); returns the measured row
    (see the module docstring)."""
    paths = [folder / f"run-{n}-{j}.mcap" for j in range(recorders)]
    epoch_ns = time.time_ns()
    recs = [RecorderActor.options(name=f"aerodaas/bench-recorder-{n}-{j}-{os.getpid()}").remote(
        ActorSpec(role="recorder", epoch_ns=epoch_ns, record=RecordSpec(path=str(p)))) for j, p in enumerate(paths)]
    ray.get([r.setup.remote() for r in recs], timeout=120)
    k = max(recorders, min(producers, n))
    cls = _producer_class()
    prods = [cls.remote(f"bench-producer-{i}", recs[i % recorders]) for i in range(k)]
    ray.get([p.ready.remote() for p in prods], timeout=300)
    start_at = time.time() + 1.0  # every producer starts together
    refs = [p.run.remote([r for r in range(n) if r % k == i], load, epoch_ns, start_at) for i, p in enumerate(prods)]
    outs = ray.get(refs)
    ray.get([r.close.remote() for r in recs], timeout=600)
    finished = time.time()
    reps = ray.get([r.recording_report.remote() for r in recs])
    for a in (*prods, *recs):
        ray.kill(a)
    row = _row(n, k, load, outs, sum(x.get("frames_dropped", 0) for x in reps), paths,
               min(o["started"] for o in outs), max(o["last_offer"] for o in outs), finished)
    return {**row, "recorders": recorders}


def _row(n: int, k: int, load: DroneLoad, outs: list[dict], rec_dropped: int, paths: list[Path], start_at: float,
         offered_until: float, finished: float) -> dict:
    """The measured row of one fleet size (files' summaries and accounting summed, throughput over the wall time
    from the first offer, ``start_at``, until the recorders finished their files, ``finished``; the drain from
    ``offered_until``, the producers' last offer, until then: delivering and writing what was still behind;
    baseline over every file)."""
    channels = [c for p in paths for c in summarize_mcap(p)["channels"]]
    recorded = sum(c["count"] for c in channels)
    accs = [account_recording([p]) for p in paths]
    size_mb = sum(p.stat().st_size for p in paths) / 1e6
    wall = finished - start_at
    drain = finished - offered_until
    frames = sum(c["count"] for c in channels if c["topic"].endswith("/camera/cam"))
    base = [baseline_write(p) for p in paths]
    secs = sum(b["seconds"] for b in base)
    return {
        "drones": n, "producers": k, "offered_items": sum(o["offered"] for o in outs),
        "frames_offered": int(n * load.duration_s * load.fps), "frames_recorded": frames,
        "frames_dropped_by_producers": sum(o["frames_dropped"] for o in outs),
        "frames_dropped_by_recorder": rec_dropped,
        "messages_recorded": recorded,
        "lost_by_accounting": None if None in accs else sum(a["lost_total"] for a in accs),
        "mb_recorded": round(size_mb, 2), "wall_s": round(wall, 2), "drain_s": round(drain, 2),
        "producer_max_lag_s": max(o["max_lag_s"] for o in outs),
        "messages_per_s": round(recorded / wall, 1), "mb_per_s": round(size_mb / wall, 2),
        "offered_mb_per_s": round(n * load.fps * _mean_size(load) / 1e6, 2),
        "send_errors": [e for o in outs for e in o["send_errors"]],
        "baseline": {"messages": sum(b["messages"] for b in base), "seconds": round(secs, 3),
                     "messages_per_s": round(sum(b["messages"] for b in base) / secs, 1),
                     "mb_per_s": round(size_mb / secs, 2)},
    }


def _mean_size(load: DroneLoad) -> float:
    return sum(len(f) for f in load.frames) / len(load.frames)


def baseline_write(path: Path) -> dict:
    """The bare baseline: every message of the recording ``path`` (read into memory first) written again with the
    ``mcap`` library directly, in this process, zstd chunks of 256 KiB. Returns ``{"messages", "seconds",
    "messages_per_s", "mb_per_s"}`` (MB of the file it wrote)."""
    with open(path, "rb") as f:
        msgs = [(s, c, m.log_time, m.data) for s, c, m in make_reader(f).iter_messages(log_time_order=True)]
    out = path.with_suffix(".baseline.mcap")
    t0 = time.perf_counter()
    with open(out, "wb") as f:
        w = Writer(f, chunk_size=256 * 1024, compression=CompressionType.ZSTD)
        w.start(profile="", library="aerodaas bench recorder baseline")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for s, c, t, data in msgs:
            if c.id not in channels:
                if s is not None and s.id not in schemas:
                    schemas[s.id] = w.register_schema(name=s.name, encoding=s.encoding, data=s.data)
                channels[c.id] = w.register_channel(topic=c.topic, message_encoding=c.message_encoding,
                                                    schema_id=schemas.get(s.id, 0) if s is not None else 0)
            w.add_message(channel_id=channels[c.id], log_time=t, data=data, publish_time=t)
        w.finish()
    dt = time.perf_counter() - t0
    mb = out.stat().st_size / 1e6
    out.unlink()
    return {"messages": len(msgs), "seconds": round(dt, 3), "messages_per_s": round(len(msgs) / dt, 1),
            "mb_per_s": round(mb / dt, 2)}


def run_recorder_bench(sizes: tuple[int, ...], load: DroneLoad, producers: int, frame_source: str,
                       recorders: int = 1) -> dict:
    """Every fleet size in ``sizes`` on one local Ray (started here, shut down at the end), with ``recorders``
    recorder actors; returns the report."""
    machine = machine_info()
    rows = []
    ray_start.ensure_ray(None)
    try:
        with tempfile.TemporaryDirectory(prefix="aerodaas-bench-recorder-") as d, \
                bench_progress("bench recorder", total=len(sizes)) as (progress, task):
            for n in sizes:
                progress.update(task, description=f"bench recorder N={n}")
                row = run_size(n, load, producers, Path(d), recorders)
                row["load_avg_1min_end"] = round(os.getloadavg()[0], 2)
                rows.append(row)
                progress.advance(task)
                progress.console.print(
                    f"recorder N={n:3d}: {row['messages_per_s']:8.0f} msg/s {row['mb_per_s']:6.2f} MB/s "
                    f"(bare mcap {row['baseline']['messages_per_s']:8.0f} msg/s {row['baseline']['mb_per_s']:6.1f} "
                    f"MB/s)  lost {row['lost_by_accounting']}  recorder dropped {row['frames_dropped_by_recorder']} "
                    f"frames  drain {row['drain_s']:.2f} s  lag {row['producer_max_lag_s']:.2f} s")
    finally:
        ray_start.shutdown_ray()
    return {"benchmark": "recorder", "machine": machine, "load": {"fps": load.fps, "odom_hz": load.odom_hz,
            "duration_s": load.duration_s, "frame_bytes": round(_mean_size(load)), "frame_size": [load.width, load.height],
            "frame_source": frame_source}, "producers": producers, "recorders": recorders, "results": rows,
            **_limit(rows)}


def _limit(rows: list[dict]) -> dict:
    """``limit``: the first size that lost messages (by the accounting or refused frames) or drained longer than
    :data:`DRAIN_LIMIT_S` (None: none did); ``ceiling``: the best throughput of a size without either."""
    bad = [r for r in rows if (r["lost_by_accounting"] or 0) > 0 or r["frames_dropped_by_recorder"] > 0
           or r["frames_dropped_by_producers"] > 0 or r["drain_s"] > DRAIN_LIMIT_S]
    good = [r for r in rows if r not in bad]
    best = max(good, key=lambda r: r["messages_per_s"], default=None)
    return {"limit": None if not bad else {"drones": bad[0]["drones"],
                                           "why": ("lost messages" if (bad[0]["lost_by_accounting"] or 0) > 0
                                                   or bad[0]["frames_dropped_by_recorder"] > 0
                                                   or bad[0]["frames_dropped_by_producers"] > 0
                                                   else f"drained {bad[0]['drain_s']} s > {DRAIN_LIMIT_S} s")},
            "ceiling": None if best is None else {"drones": best["drones"], "messages_per_s": best["messages_per_s"],
                                                  "mb_per_s": best["mb_per_s"]},
            "drain_limit_s": DRAIN_LIMIT_S}


def main(a: argparse.Namespace) -> int:
    """``aerodaas bench recorder`` with the options of :mod:`aerodaas.bench.parsers`: checks them (exit 2 naming a bad
    one), runs the benchmark and prints its report; returns the exit code."""
    sizes = tuple(a.drones) if a.drones else DEFAULT_SIZES
    for name, ok, val in (("--drones", all(s >= 1 for s in sizes), list(sizes)),
                          ("--duration", a.duration > 0, a.duration), ("--fps", a.fps > 0, a.fps),
                          ("--odom-hz", a.odom_hz > 0, a.odom_hz), ("--producers", a.producers >= 1, a.producers),
                          ("--recorders", a.recorders >= 1, a.recorders),
                          ("--width/--height", a.width >= 16 and a.height >= 16, f"{a.width}x{a.height}")):
        if not ok:
            print(f"aerodaas bench recorder: {name} must be positive (frames at least 16x16), got {val}",
                  file=sys.stderr)
            return 2
    frames, source = bench_frames(a.width, a.height)
    load = DroneLoad(a.fps, a.odom_hz, a.duration, frames, a.width, a.height)
    report = run_recorder_bench(sizes, load, a.producers, source, a.recorders)

    emit_report(report, a.out, a.json)
    if not a.json:
        print_report(format_table(report))
    return 0


def format_table(report: dict) -> str:
    """The report as a text table (one line per fleet size, the limit and ceiling below)."""
    lines = ["drones  msg/s    MB/s  bare msg/s  bare MB/s  lost  rec.dropped  drain s  lag s"]
    for r in report["results"]:
        b = r["baseline"]
        lines.append(f"{r['drones']:6d} {r['messages_per_s']:6.0f} {r['mb_per_s']:7.2f} {b['messages_per_s']:11.0f} "
                     f"{b['mb_per_s']:10.1f} {r['lost_by_accounting'] or 0:5d} {r['frames_dropped_by_recorder']:12d} "
                     f"{r['drain_s']:8.2f} {r['producer_max_lag_s']:6.2f}")
    lines.append(f"limit: {report['limit']}  ceiling: {report['ceiling']}")
    return "\n".join(lines)
