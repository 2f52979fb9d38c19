"""Benchmarks behind ``aerodaas bench <name>``.

Each benchmark is a module here exposing ``add_parser(bench_subparsers)``, which registers its sub-command (its
options and a ``func(args) -> exit code`` default). :func:`add_parsers` registers them all; the CLI calls it
once, and wraps each ``func`` in :class:`ReportOnlyStdout`: a benchmark prints its report with
:func:`aerodaas.bench.output.print_report`, and whatever else it, Ray or a child process prints goes to standard
error. Modules keep their heavy imports inside functions so ``aerodaas`` starts fast.
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
from collections.abc import Callable


def machine_info() -> dict:
    """Where a benchmark ran: CPU count (and the CPUs this process may use), total memory in GiB, the 1-minute
    load average when the benchmark started (a busy machine shows here), Python version and implementation, Ray's
    version, platform string, processor."""
    from importlib.metadata import PackageNotFoundError, version

    import psutil

    try:
        ray_version = version("ray")
    except PackageNotFoundError:
        ray_version = None
    return {
        "cpu_count": os.cpu_count(),
        "cpus_usable": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        "memory_gib": round(psutil.virtual_memory().total / 2**30, 1),
        "load_avg_1min": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
        "python": platform.python_version(),
        "implementation": platform.python_implementation(),
        "ray": ray_version,
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "executable": sys.executable,
    }


class ReportOnlyStdout:
    """A benchmark's ``func(args) -> exit code`` run inside :func:`aerodaas.bench.output.report_only_stdout`, so
    that its standard output carries its report alone (issue 49 item 7). In the ``aerodaas`` process itself
    (``args.own_process``) the redirection stays until the exit, where Ray's shutdown may still print."""

    def __init__(self, func: Callable[[argparse.Namespace], int]) -> None:
        self.func = func

    def __call__(self, args: argparse.Namespace) -> int:
        from aerodaas.bench.output import report_only_stdout

        with report_only_stdout(restore=not args.own_process):
            return self.func(args)


def add_parsers(bench_subparsers: argparse._SubParsersAction) -> None:
    """Register every ``aerodaas bench`` sub-command on ``bench_subparsers``, each one's ``func`` wrapped in
    :class:`ReportOnlyStdout`."""
    from aerodaas.bench import (detect, fleet, overhead, raypath, recorder, schedulers_cli, startup, tello_video,
                                tours, tracks, video)

    tours.add_parser(bench_subparsers)
    schedulers_cli.add_parser(bench_subparsers)
    overhead.add_parser(bench_subparsers)
    fleet.add_parser(bench_subparsers)
    startup.add_parser(bench_subparsers)
    tello_video.add_parser(bench_subparsers)
    raypath.add_parser(bench_subparsers)
    detect.add_parser(bench_subparsers)
    tracks.add_parser(bench_subparsers)
    video.add_parser(bench_subparsers)
    recorder.add_parser(bench_subparsers)
    for parser in bench_subparsers.choices.values():
        parser.set_defaults(func=ReportOnlyStdout(parser.get_default("func")))
