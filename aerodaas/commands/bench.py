"""``aerodaas bench BENCHMARK ...``: the benchmarks, each of which registers its own sub-command
(:func:`aerodaas.bench.parsers.add_parsers`, which imports no benchmark module until one runs)."""
from __future__ import annotations

from aerodaas.bench.parsers import add_parsers


def add_parser(sub) -> None:
    """``aerodaas bench`` and its benchmarks' sub-commands."""
    bench = sub.add_parser("bench", help="benchmarks: tours, schedulers, overhead, fleet, startup, tello-video, raypath; "
                                         "--json for JSON output")
    add_parsers(bench.add_subparsers(dest="bench_cmd", required=True, metavar="BENCHMARK"))
