"""``aerodaas layout``: a Foxglove layout for a recording."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

def run(args: argparse.Namespace) -> int:
    """``aerodaas layout RUN.mcap [--out FILE]``: a Foxglove layout for the recording's robot, camera and detections
    (:func:`aerodaas.liveview.layout.layout_for_recording`); exit 2 for a missing or foreign file."""
    from aerodaas.liveview.layout import layout_for_recording  # lazy: CLI start-up (OpenCV and MCAP)

    try:
        text = json.dumps(layout_for_recording(args.file), indent=2) + "\n"
        if args.out:
            Path(args.out).write_text(text)
            print(f"aerodaas layout: wrote {args.out} (Foxglove: Layouts -> Import from file)")
        else:
            sys.stdout.write(text)
    except (OSError, ValueError) as e:
        print(f"aerodaas layout: {e}", file=sys.stderr)
        return 2
    return 0


def add_parser(sub) -> None:
    """``aerodaas layout RUN.mcap [--out FILE]``."""
    ly = sub.add_parser("layout", help="write a Foxglove layout (camera + detections, 3D, map, state, battery/altitude) "
                                       "for a recording")
    ly.add_argument("file")
    ly.add_argument("--out", metavar="FILE", help="output file (default: standard output)")
    ly.set_defaults(func=run)
