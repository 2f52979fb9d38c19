"""The options of the ``aerodaas bench`` benchmarks (:func:`add_parsers`, called by every ``aerodaas`` start).

This module and :mod:`aerodaas.bench.options` import nothing beyond the standard library: a benchmark's own module
(NumPy, Ray, the runtime) is imported by its handler when the benchmark runs, one marked lazy import each
(``aerodaas --help`` costs no benchmark). Each handler calls the benchmark module's ``main(args) -> exit code``,
wrapped in :class:`ReportOnlyStdout`: a benchmark prints its report with :func:`aerodaas.bench.output.print_report`,
and whatever else it, Ray or a child process prints goes to standard error.
"""
from __future__ import annotations

import argparse
from collections.abc import Callable

from aerodaas.bench import schedulers_cli
from aerodaas.bench.options import (ALL_LAYOUTS, FRAME_META_SOURCES, TOUR_SIZES, VIDEO_READERS, VIDEO_SIZES,
                                    positive_int, tour_sizes)
from aerodaas.bench.output import report_only_stdout


class ReportOnlyStdout:
    """A benchmark's ``func(args) -> exit code`` run inside :func:`aerodaas.bench.output.report_only_stdout`, so
    that its standard output carries its report alone. In the ``aerodaas`` process itself
    (``args.own_process``) the redirection stays until the exit, where Ray's shutdown may still print."""

    def __init__(self, func: Callable[[argparse.Namespace], int]) -> None:
        self.func = func

    def __call__(self, args: argparse.Namespace) -> int:
        with report_only_stdout(restore=not args.own_process):
            return self.func(args)


def add_parsers(bench_subparsers: argparse._SubParsersAction) -> None:
    """Register every ``aerodaas bench`` sub-command on ``bench_subparsers``, each one's ``func`` wrapped in
    :class:`ReportOnlyStdout`."""
    add_tours(bench_subparsers)
    schedulers_cli.add_parser(bench_subparsers)
    add_overhead(bench_subparsers)
    add_fleet(bench_subparsers)
    add_fleet_model(bench_subparsers)
    add_startup(bench_subparsers)
    add_tello_video(bench_subparsers)
    add_raypath(bench_subparsers)
    add_detect(bench_subparsers)
    add_tracks(bench_subparsers)
    add_video(bench_subparsers)
    add_recorder(bench_subparsers)
    for parser in bench_subparsers.choices.values():
        parser.set_defaults(func=ReportOnlyStdout(parser.get_default("func")))


def add_fleet(sub: argparse._SubParsersAction) -> None:
    """Register ``aerodaas bench fleet`` on the ``bench`` sub-command\'s sub-parsers ``sub``."""
    p = sub.add_parser("fleet", help="N simulated drones on one node: missed control ticks, dropped frames, CPU, RSS")
    p.add_argument("--drones", type=int, action="append", help="fleet size (repeatable; default 1 5 10 20 40)")
    p.add_argument("--duration", type=float, default=30.0, help="seconds of flight per size (real time)")
    p.add_argument("--drones-per-actor", type=int, action="append", dest="per_actor",
                   help="drones sharing one drone actor (repeatable; default 1)")
    p.add_argument("--run", action="append", dest="runs", metavar="N:K",
                   help="one fleet of N drones, K per drone actor (repeatable; replaces the --drones x "
                        "--drones-per-actor grid, so one invocation can hold 20:1, 40:1 and 100:10)")
    p.add_argument("--profile", action="store_true",
                   help="per run, where one drone actor's CPU and memory go (per-thread CPU from /proc, "
                        "apportioned by py-spy when it is on the PATH) and the node's processes' CPU")
    p.add_argument("--no-camera", action="store_true",
                   help="drones without cameras: odometry, stat-stream and control only, no frame rendered, "
                        "recorded or analysed (a formation or swarm; default: a 640x480 camera at 15 FPS each)")
    p.add_argument("--edge-nodes", type=int, default=None,
                   help="run each fleet on a fresh local cluster of this many tier=edge nodes (>= 1; raylets of "
                        "their own, loopback, token auth; the first is the head), drones spread over them by node "
                        "label, recorded with one recorder per node; reports each node (default: the local Ray)")
    p.add_argument("--json", action="store_true", help="print the JSON report")
    p.add_argument("--out", help="also write the JSON report to this file")
    p.add_argument("--plot", help="write the curve as a PNG to this file (default: no figure; a benchmark writes "
                                  "no file it was not given)")
    p.set_defaults(func=_run_fleet)


def _run_fleet(args: argparse.Namespace) -> int:
    from aerodaas.bench.fleet import main  # lazy: CLI start-up

    return main(args)


def add_fleet_model(sub: argparse._SubParsersAction) -> None:
    """Register ``aerodaas bench fleet-model`` on the ``bench`` sub-command\'s sub-parsers ``sub``."""
    p = sub.add_parser("fleet-model", help="fit a cost model to bench fleet --edge-nodes reports and project the "
                                           "nodes a fleet needs (CPU, memory, GCS actors, recorder ceiling)")
    p.add_argument("reports", nargs="+", metavar="RUN.json", help="bench fleet --edge-nodes N --json reports")
    p.add_argument("--drones", type=int, default=1000, help="fleet to project (default 1000)")
    p.add_argument("--node-cores", type=float, help="cores of one edge node (default: the measured machine's)")
    p.add_argument("--node-mem-gib", type=float, help="memory of one edge node, GiB (default: the measured "
                                                      "machine's)")
    p.add_argument("--recorder-msgs-per-s", type=float, default=8000.0,
                   help="one recorder's message ceiling (default 8000: bench recorder, docs/results/recorder.md)")
    p.add_argument("--recorder-mb-per-s", type=float, default=15.0,
                   help="one recorder's byte ceiling, MiB/s (default 15: bench recorder, docs/results/recorder.md)")
    p.add_argument("--mb-per-drone", type=float, help="recorded MiB/s of one drone instead of the fitted one (e.g. a "
                                                      "real camera's frames; default: as the runs recorded)")
    p.add_argument("--json", action="store_true", help="print the JSON projection")
    p.add_argument("--out", help="also write the JSON projection to this file")
    p.set_defaults(func=_run_fleet_model)


def _run_fleet_model(args: argparse.Namespace) -> int:
    from aerodaas.bench.fleet_model import main  # lazy: CLI start-up

    return main(args)


def add_overhead(sub: argparse._SubParsersAction) -> None:
    """Register ``aerodaas bench overhead`` on the ``bench`` sub-command\'s sub-parsers ``sub``."""
    p = sub.add_parser("overhead", help="per-frame framework overhead (camera -> detector -> follow -> scheduler -> "
                                        "drone) vs a bare loop, a naive Ray pipeline and dora-rs, interleaved")
    p.add_argument("--duration", type=float, default=20.0, help="measured seconds per pipeline and configuration")
    p.add_argument("--window", type=float, default=5.0, help="seconds per round-robin window")
    p.add_argument("--settle", type=float, default=4.0,
                   help="seconds each AeroDaaS mission flies at its altitude before its window, not measured (the "
                        "follow settling on its target after a climb at 4 m/s; default 4)")
    p.add_argument("--stub-ms", type=float, default=10.0, help="inference time of the fixed-cost stub detector, ms")
    p.add_argument("--detector", choices=["stub", "yolox", "both"], default="both")
    p.add_argument("--resolution", action="append", help="WxH (repeatable; default 1280x720 and 640x480)")
    p.add_argument("--layout", choices=[*ALL_LAYOUTS, "both", "all"], default="all",
                   help="AeroDaaS layout(s) to fly: colocated (zero hops), actors (the detector in its own actor, "
                        "same-node channel), actors-ray (its own actor, Ray calls), both (colocated + actors), "
                        "all (default); LAYOUT+lockstep flies LAYOUT under the lock-step clock")
    p.add_argument("--lockstep", action="store_true",
                   help="also fly the actors layout under the lock-step clock the shipped apps use "
                        "(row actors+lockstep: same channel, the clock waits for each frame's cascade)")
    p.add_argument("--record", action="store_true", help="record the AeroDaaS runs to MCAP (recording cost shows)")
    p.add_argument("--json", action="store_true", help="print the JSON report")
    p.add_argument("--out", help="also write the JSON report to this file")
    p.set_defaults(func=_run_overhead)


def _run_overhead(args: argparse.Namespace) -> int:
    from aerodaas.bench.overhead import main  # lazy: CLI start-up

    return main(args)


def add_raypath(sub: argparse._SubParsersAction) -> None:
    """Register ``aerodaas bench raypath`` on the ``bench`` sub-command\'s sub-parsers ``sub``."""
    p = sub.add_parser("raypath", help="where Ray's call path spends its time for one 1280x720 frame hop "
                                       "(put, call with an ObjectRef, get, inline and by-value calls)")
    p.add_argument("--repeat", type=int, default=300, help="measured repetitions per step")
    p.add_argument("--json", action="store_true", help="print the JSON report")
    p.add_argument("--out", help="also write the JSON report to this file")
    p.set_defaults(func=_run_raypath)


def _run_raypath(args: argparse.Namespace) -> int:
    from aerodaas.bench.raypath import main  # lazy: CLI start-up

    return main(args)


def add_recorder(sub: argparse._SubParsersAction) -> None:
    """Register ``aerodaas bench recorder`` on the ``bench`` sub-command\'s sub-parsers ``sub``."""
    p = sub.add_parser("recorder", help="the run's recorder actor: messages/s and MB/s into one MCAP with frames, "
                                        "the fleet size where it drops or back-pressures, beside bare mcap")
    p.add_argument("--drones", type=int, action="append", help="fleet size (repeatable; default 5 10 20 40 80)")
    p.add_argument("--duration", type=float, default=10.0, help="seconds of offering per size (default 10)")
    p.add_argument("--fps", type=float, default=5.0, help="frames per second per drone (default 5)")
    p.add_argument("--odom-hz", type=float, default=10.0, help="odometry samples per second per drone (default 10)")
    p.add_argument("--width", type=int, default=1280, help="frame width, px (default 1280)")
    p.add_argument("--height", type=int, default=720, help="frame height, px (default 720)")
    p.add_argument("--producers", type=int, default=2, help="producer actors the drones are spread over (default 2; "
                                                            "at least --recorders)")
    p.add_argument("--recorders", type=int, default=1, help="recorder actors, each writing its own file with its own "
                                                            "accounting, as recording.per_node makes one per node "
                                                            "(default 1: the run's one recorder)")
    p.add_argument("--json", action="store_true", help="print the JSON report")
    p.add_argument("--out", help="also write the JSON report to this file")
    p.set_defaults(func=_run_recorder)


def _run_recorder(args: argparse.Namespace) -> int:
    from aerodaas.bench.recorder import main  # lazy: CLI start-up

    return main(args)


def add_startup(sub: argparse._SubParsersAction) -> None:
    """Register ``aerodaas bench startup`` on the ``bench`` sub-command\'s sub-parsers ``sub``."""
    p = sub.add_parser("startup", help="seconds from `aerodaas run APP` to the first processed frame (cold Ray)")
    p.add_argument("--app", default=None, help="application (default: apps/vehicle_tracking.py next to this install)")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--mode", choices=["cold", "attached", "both"], default="both",
                   help="cold Ray start, attached to `aerodaas up`'s cluster, or both (default)")
    p.add_argument("--warm-workers", type=int, default=None,
                   help="warm workers of the `aerodaas up` cluster of attached runs (default: aerodaas up's; 0: none)")
    p.add_argument("--json", action="store_true", help="print the JSON report")
    p.add_argument("--out", help="also write the JSON report to this file")
    p.set_defaults(func=_run_startup)


def _run_startup(args: argparse.Namespace) -> int:
    from aerodaas.bench.startup import main  # lazy: CLI start-up

    return main(args)


def add_detect(sub: argparse._SubParsersAction) -> None:
    """Register ``aerodaas bench detect`` on the ``bench`` sub-command\'s sub-parsers ``sub``."""
    p = sub.add_parser("detect", help="score a detector on annotated images (COCO JSON or YOLO txt): recall/precision, "
                                      "AP50, ms/frame; --sweep over input size, tiling, threshold")
    p.add_argument("--images", required=True, help="folder of the images")
    p.add_argument("--annotations", required=True,
                   help="COCO .json file, folder of YOLO .txt labels, or VisDrone-DET annotations folder")
    p.add_argument("--annotation-format", default="auto", choices=["auto", "coco", "yolo", "visdrone"],
                   help="auto: a .json file is COCO, a folder YOLO; visdrone: a VisDrone-DET annotations folder")
    p.add_argument("--names", nargs="+", help="class names of YOLO labels (else classes.txt in the label folder)")
    p.add_argument("--model", default="yolox_nano", help="shipped model name (yolox_nano, nanodet_plus_m_416)")
    p.add_argument("--model-path", help="bring your own ONNX model")
    p.add_argument("--format", default="auto", choices=["auto", "yolox", "nanodet", "ultralytics"])
    p.add_argument("--classes", nargs="+", help="classes to score (default: those annotated)")
    p.add_argument("--group", action="append",
                   help="NAME=a,b,c: score annotated and detected classes a, b, c as one class NAME (e.g. "
                        "vehicle=car,truck,bus,minibus: a car the model calls a truck is found); repeatable")
    p.add_argument("--thresholds", nargs="+", type=float, default=[0.15])
    p.add_argument("--input-sizes", nargs="+", default=["0"],
                   help="input sizes for a dynamic-axes model: N (N x N) or HxW pixels (0: the model's own)")
    p.add_argument("--tiles", nargs="+", type=int, default=[0], help="tile sizes in pixels (0: whole frame)")
    p.add_argument("--overlap", type=float, default=0.2)
    p.add_argument("--merge", default="greedynmm", choices=["nms", "greedynmm"])
    p.add_argument("--no-full-frame", action="store_true", help="tiles only, without the whole frame")
    p.add_argument("--agnostic-nms", action="store_true")
    p.add_argument("--sweep", action="store_true", help="every combination of sizes, tiles and thresholds")
    p.add_argument("--threads", type=int, default=1,
                   help="onnxruntime intra-op threads (1: on a shared, loaded machine 2 threads spin and run slower)")
    p.add_argument("--repeat", type=int, default=3, help="timed runs per frame (the median is kept)")
    p.add_argument("--frame-width", type=int, default=0,
                   help="resize each image to this width first (e.g. 1920), boxes scaled alike (0: as stored)")
    p.add_argument("--limit", type=int, default=0, help="score only the first N annotated images")
    p.add_argument("--frame-meta", default="auto", choices=list(FRAME_META_SOURCES),
                   help="per-frame view angle and altitude for the breakdowns: hit-uav (from HIT-UAV file names "
                        "T_H_A_S_N.jpg), auto (hit-uav when every file name has that form), none")
    p.add_argument("--out", help="write the JSON report here")
    p.add_argument("--plot", help="write the PR-curve PNG here")
    p.add_argument("--json", action="store_true", help="print the JSON report")
    p.set_defaults(func=_run_detect)


def _run_detect(args: argparse.Namespace) -> int:
    from aerodaas.bench.detect import main  # lazy: CLI start-up

    return main(args)


def add_tours(bench_subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``aerodaas bench tours`` on the ``bench`` sub-command's subparsers."""
    t = bench_subparsers.add_parser(
        "tours", help="tour length vs exact optimum / lower bound, and planning time, per trajectory scheduler",
        description="Tour length (vs the exact optimum for n <= 12, else vs a proven lower bound) and planning "
                    "time of the trajectory schedulers on seeded random instances, plus the paper's "
                    "disaster-survey case.")
    t.add_argument("--json", action="store_true", help="print the result as JSON instead of a table")
    t.add_argument("--out", metavar="FILE", help="also write the JSON result to FILE")
    t.add_argument("--seed", type=int, default=0, help="seed of the random instances (default 0)")
    t.add_argument("--sizes", type=tour_sizes, default=list(TOUR_SIZES),
                   help="comma-separated waypoint counts (default 10,20,50,100,200; exact reference for n <= 12)")
    t.add_argument("--instances", type=positive_int, default=5, help="instances per size (default 5)")
    t.add_argument("--repeats", type=positive_int, default=3, help="timed runs per instance and scheduler (default 3)")
    t.set_defaults(func=_run_tours)
    return t


def _run_tours(args: argparse.Namespace) -> int:
    from aerodaas.bench.tours import main  # lazy: CLI start-up

    return main(args)


def add_tello_video(bench_subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``aerodaas bench tello-video``."""
    t = bench_subparsers.add_parser("tello-video", help="Tello H.264 decode: PyAV vs OpenCV (latency, ms/frame)",
                                    description="How to decode the Tello's H.264 UDP stream: PyAV vs OpenCV's "
                                                "FFmpeg backend.")
    t.add_argument("--width", type=int, default=960)
    t.add_argument("--height", type=int, default=720)
    t.add_argument("--fps", type=float, default=30.0)
    t.add_argument("--seconds", type=float, default=8.0, help="live streaming time per decoder (default 8)")
    t.add_argument("--json", action="store_true", help="print the JSON report (it is printed either way: this "
                                                       "benchmark has no table)")
    t.set_defaults(func=_run_tello_video)
    return t


def _run_tello_video(args: argparse.Namespace) -> int:
    from aerodaas.bench.tello_video import main  # lazy: CLI start-up

    return main(args)


def add_tracks(sub: argparse._SubParsersAction) -> None:
    """Register ``aerodaas bench tracks`` on the ``bench`` sub-command\'s sub-parsers ``sub``."""
    p = sub.add_parser("tracks", help="score a simulated run's recorded tracks against the simulator's truth: id "
                                      "switches per 100 frames, geo-location error (m)")
    p.add_argument("recording", help="the run's MCAP file (aerodaas run APP --record FILE)")
    p.add_argument("--altitude", nargs=2, type=float, default=[19.0, 21.0], metavar=("MIN", "MAX"),
                   help="score frames taken at this altitude above home, metres (default 19 21)")
    p.add_argument("--gate", type=float, default=3.0, help="largest track-to-truth distance that matches, metres")
    p.add_argument("--out", help="write the JSON report here")
    p.add_argument("--json", action="store_true", help="print the JSON report (it is printed either way: this "
                                                       "benchmark has no table)")
    p.set_defaults(func=_run_tracks)


def _run_tracks(args: argparse.Namespace) -> int:
    from aerodaas.bench.tracks import main  # lazy: CLI start-up

    return main(args)


def add_video(sub: argparse._SubParsersAction) -> None:
    """Register ``aerodaas bench video`` on the ``bench`` sub-command\'s sub-parsers ``sub``."""
    p = sub.add_parser("video", help="video stream latency (ArUco frame counter) and decode CPU: ours vs bare PyAV "
                                     "vs OpenCV CAP_FFMPEG vs a GStreamer appsink, at 720p and 1080p")
    p.add_argument("--readers", default=",".join(VIDEO_READERS), help=f"comma-separated, of {list(VIDEO_READERS)}")
    p.add_argument("--sizes", default="720p,1080p", help=f"comma-separated, of {list(VIDEO_SIZES)}")
    p.add_argument("--fps", type=float, default=30.0, help="stream frame rate (1-120)")
    p.add_argument("--seconds", type=float, default=10.0, help="seconds each reader reads")
    p.add_argument("--out", help="also write the JSON report here")
    p.add_argument("--json", action="store_true", help="print the JSON report (it is printed either way: this "
                                                       "benchmark has no table)")
    p.set_defaults(func=_run_video)


def _run_video(args: argparse.Namespace) -> int:
    from aerodaas.bench.video import main  # lazy: CLI start-up

    return main(args)
