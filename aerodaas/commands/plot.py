"""``aerodaas plot``: a recording's figures as PNGs (drawn by :func:`aerodaas.tools.plot.plot_run`)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def run(args: argparse.Namespace) -> int:
    """``aerodaas plot FILE [--out DIR]``: the figures of :func:`aerodaas.tools.plot.plot_run` (matplotlib is
    imported only for this command), their paths printed. Exit 0 when figures were written, 2 for a missing or
    unreadable file or an output folder that cannot be created, 1 when the recording has nothing to plot."""
    from aerodaas.tools.plot import plot_run  # lazy: CLI start-up (matplotlib)

    src = Path(args.file)
    if not src.exists():
        print(f"aerodaas plot: recording {str(src)!r} not found", file=sys.stderr)
        return 2
    if not src.is_file():
        print(f"aerodaas plot: {str(src)!r} is not a file", file=sys.stderr)
        return 2
    try:
        written = plot_run(src, args.out)
    except ValueError as e:
        print(f"aerodaas plot: cannot read {str(src)!r}: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"aerodaas plot: {e}", file=sys.stderr)
        return 2
    if not written:
        print(f"aerodaas plot: nothing to plot in {str(src)!r}", file=sys.stderr)
        return 1
    for p in written.values():
        print(p)
    return 0


def add_parser(sub) -> None:
    """``aerodaas plot FILE [--out DIR]``."""
    pl = sub.add_parser("plot", help="draw a recording's figures (trajectory, battery/altitude, latency) as PNGs")
    pl.add_argument("file", help="MCAP recording (an unfinished, crashed one plots what is readable)")
    pl.add_argument("--out", metavar="DIR", help="output folder (default: <stem>_plots/ next to the recording)")
    pl.set_defaults(func=run)
