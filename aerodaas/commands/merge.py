"""``aerodaas merge``: one run recorded in several MCAP files (one recorder per node) merged into one."""
from __future__ import annotations

import argparse
import sys


def run(args: argparse.Namespace) -> int:
    """``aerodaas merge FILE [FILE ...] --out OUT``: :func:`aerodaas.recording.merge.merge_recordings` (channels and
    schemas de-duplicated, messages in log-time order, the files' accounting summed). Exit 0, 2 for a missing,
    foreign or unfinished input, an output among the inputs or one that cannot be written."""
    from aerodaas.recording.merge import merge_recordings  # lazy: CLI start-up (MCAP)

    try:
        r = merge_recordings(args.files, args.out)
    except (OSError, ValueError) as e:
        print(f"aerodaas merge: {e}", file=sys.stderr)
        return 2
    print(f"{r['out']}: {len(r['files'])} recordings merged: {r['messages']} messages on {r['channels']} channels "
          f"({r['accounting_files']} with accounting, summed)")
    return 0


def add_parser(sub) -> None:
    """``aerodaas merge FILE [FILE ...] --out OUT``."""
    m = sub.add_parser("merge", help="merge the MCAP files of one run (one recorder per node) into one, "
                                     "accounting summed")
    m.add_argument("files", nargs="+", help="the run's recordings (RUN.mcap RUN.node-*.mcap)")
    m.add_argument("--out", required=True, help="the merged file (must not be one of the inputs)")
    m.set_defaults(func=run)
