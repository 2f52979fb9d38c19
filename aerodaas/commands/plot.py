"""``aerodaas plot``: a recording's figures as PNGs."""
from __future__ import annotations

import argparse

def run(args: argparse.Namespace) -> int:
    """``aerodaas plot FILE [--out DIR]``: :func:`aerodaas.tools.plot.cmd_plot` (matplotlib is imported only for
    this command)."""
    from aerodaas.tools.plot import cmd_plot  # lazy: CLI start-up (matplotlib)

    return cmd_plot(args)


def add_parser(sub) -> None:
    """``aerodaas plot FILE [--out DIR]``."""
    pl = sub.add_parser("plot", help="draw a recording's figures (trajectory, battery/altitude, latency) as PNGs")
    pl.add_argument("file", help="MCAP recording (an unfinished, crashed one plots what is readable)")
    pl.add_argument("--out", metavar="DIR", help="output folder (default: <stem>_plots/ next to the recording)")
    pl.set_defaults(func=run)
