"""``aerodaas info``: summarise an MCAP recording."""
from __future__ import annotations

import argparse
import json
import sys

def run(args: argparse.Namespace) -> int:
    """``aerodaas info FILE [--json]``: a recording's messages, channels, mission outcome, lost-message accounting
    and video streams (:func:`aerodaas.recording.reader.summarize_mcap`). Exit 0, 2 for a missing or foreign file."""
    from aerodaas.recording.video_summary import format_video_streams, video_streams  # lazy: CLI start-up (MCAP)
    from aerodaas.recording.reader import summarize_mcap  # lazy: CLI start-up (MCAP)

    try:
        s = summarize_mcap(args.file)
        s["video"] = video_streams(args.file, s["channels"])  # stream cameras: counters, capture-to-hand-off
    except (OSError, ValueError) as e:
        print(f"aerodaas info: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(s, indent=2, default=str))
        return 0
    print(f"{s['path']}: {s['message_count']} messages, {s['duration_s']:.1f} s, "
          f"{'finished' if s['finished'] else 'UNFINISHED (recovered what was readable)'}")
    mission = s.get("mission") or {}
    print(f"mission outcome: {mission.get('outcome')}   final state: {mission.get('final_state')}")
    w = max((len(c["topic"]) for c in s["channels"]), default=10)
    for c in s["channels"]:
        print(f"  {c['topic']:<{w}}  {c['schema']:<28} {c['count']:>7} msgs  {c['rate_hz']:7.2f} Hz")
    acc = s.get("accounting")
    if acc is not None:  # per channel: the producers' sequence numbers against the file's messages
        print(f"accounting: {acc['lost_total']} numbered messages lost" + (":" if acc["lost"] else ""))
        for topic, n in acc["lost"].items():
            c = acc["channels"][topic]
            print(f"  {topic:<{w}}  {n} lost, {c['recorded']} of {c['produced'] - c['duplicates']} recorded")
    if s["video"]:
        print("\n".join(["video streams:"] + format_video_streams(s["video"])))
    return 0


def add_parser(sub) -> None:
    """``aerodaas info FILE [--json]``."""
    i = sub.add_parser("info", help="summarise an MCAP recording")
    i.add_argument("file")
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=run)
