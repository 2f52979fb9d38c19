"""``aerodaas recover``: finish an unfinished recording."""
from __future__ import annotations

import argparse
import sys

def run(args: argparse.Namespace) -> int:
    """``aerodaas recover FILE [--out OUT]``: see :mod:`aerodaas.recording.recover`; a recording in segments (its
    recorder actor was restarted: ``FILE``, ``FILE.1.mcap`` ...) is joined into one file
    (:func:`aerodaas.recording.segments.join_segments`). Exit 0 (also for a file that was already finished), 2 for a
    missing or non-MCAP file or an output that cannot be written."""
    from aerodaas.recording.recover import recover_mcap  # lazy: CLI start-up (MCAP)
    from aerodaas.recording.segments import join_segments, list_segments  # lazy: CLI start-up (MCAP)

    try:
        if len(list_segments(args.file)) > 1:
            j = join_segments(args.file, args.out)
            print(f"{j['out']}: {len(j['segments'])} segments ({', '.join(j['segments'])}) joined, finished and "
                  f"indexed: {j['messages']} messages on {j['channels']} channels")
            return 0
        r = recover_mcap(args.file, args.out)
    except (OSError, ValueError) as e:
        print(f"aerodaas recover: {e}", file=sys.stderr)
        return 2
    if r["was_finished"] and r["messages"] is None:
        print(f"{r['path']}: already finished; nothing to do")
    else:
        print(f"{r['out']}: finished and indexed, {r['messages']} messages on {r['channels']} channels recovered")
    return 0


def add_parser(sub) -> None:
    """``aerodaas recover FILE [--out OUT]``."""
    rc = sub.add_parser("recover", help="rewrite an unfinished (crashed, killed) MCAP recording as a finished, "
                                        "indexed one")
    rc.add_argument("file")
    rc.add_argument("--out", help="write here instead of replacing FILE")
    rc.set_defaults(func=run)
