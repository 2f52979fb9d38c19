"""The benchmarks' option values shared by their parsers (:mod:`aerodaas.bench.parsers`, imported by every
``aerodaas`` start) and the benchmarks themselves: names, defaults and ``argparse`` types, with no import beyond the
standard library, so that ``aerodaas --help`` never imports NumPy, Ray or a benchmark."""
from __future__ import annotations

import argparse

#: ``bench tours``: waypoint counts of the random instances
TOUR_SIZES = (10, 20, 50, 100, 200)

#: ``bench overhead``: the AeroDaaS layouts flown, and the suffix that flies one under the lock-step clock
LAYOUTS = ("colocated", "actors", "actors-ray")
LOCKSTEP = "+lockstep"
ALL_LAYOUTS = (*LAYOUTS, *(f"{x}{LOCKSTEP}" for x in LAYOUTS))

#: ``bench video``: the stream readers compared and the frame sizes (name -> (width, height) pixels)
VIDEO_READERS = ("ours", "pyav", "opencv", "gstreamer")
VIDEO_SIZES = {"720p": (1280, 720), "1080p": (1920, 1080)}

#: ``bench detect --frame-meta``: the same tuple as :data:`aerodaas.perception.breakdown.FRAME_META_SOURCES`
#: (kept here because that module imports NumPy; ``tests/bench/test_bench_json_stdout.py`` checks they agree)
FRAME_META_SOURCES = ("auto", "hit-uav", "none")

#: ``bench schedulers``: the workload loads, the emulation-error bound (ms), drones per edge and frames/s per drone
LOADS = ("LIGHT", "MEDIUM", "HEAVY")
EMULATION_BOUND_MS = 10.0
DEFAULT_DRONES_PER_EDGE = 3
DEFAULT_FPS = 1.0
#: network-variability scenarios: name -> what it adds to every cloud round trip (NetworkModel specs)
SCENARIOS = {
    "none": "no extra latency (the workload's cloud_ms is the measured Lambda round trip)",
    "step": "+200 ms on every cloud call sent in the last 20 s of each minute (stand-in for the reference's "
            "artificial latency variability, deploy_nwvar_og_artif_lat.py)",
    "walk": "a seeded random walk of +-25 ms per second within [0, 250] ms (slow drift, walk:25,250)",
}


def positive_int(text: str) -> int:
    """``argparse`` type: an integer >= 1. Raises argparse.ArgumentTypeError naming the text otherwise."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


def tour_sizes(text: str) -> list[int]:
    """``argparse`` type of ``bench tours --sizes``: comma-separated positive integers. Raises
    argparse.ArgumentTypeError naming the text otherwise."""
    try:
        sizes = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sizes takes comma-separated integers, got {text!r}") from None
    if not sizes or any(n < 1 for n in sizes):
        raise argparse.ArgumentTypeError(f"--sizes needs positive integers, got {text!r}")
    return sizes
