"""``aerodaas bench BENCHMARK ...``: the benchmarks, each of which registers its own sub-command
(:func:`aerodaas.bench.add_parsers`)."""
from __future__ import annotations


def add_parser(sub) -> None:
    """``aerodaas bench`` and its benchmarks' sub-commands."""
    from aerodaas.bench import add_parsers

    bench = sub.add_parser("bench", help="benchmarks: tours, schedulers, overhead, fleet, startup, tello-video, raypath; "
                                         "--json for JSON output")
    add_parsers(bench.add_subparsers(dest="bench_cmd", required=True, metavar="BENCHMARK"))
