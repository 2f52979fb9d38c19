"""The accounting of a recorded run, read from its files: what each channel lost (the rules and the arithmetic:
:mod:`aerodaas.recording.channel_accounts`, whose names are re-exported here).

The arithmetic lives in :mod:`~aerodaas.recording.channel_accounts` because the reader
(:func:`aerodaas.recording.reader.summarize_mcap`) applies it to each file and this module reads the files with
the reader: the two import it from below (no import cycle).
"""
from __future__ import annotations

import os
from typing import Any

from aerodaas.recording.channel_accounts import (ACCOUNTING_TOPIC, ANALYTICS_OUTPUT_SUFFIXES, ChannelAccount,
                                                 account_channels, accounting_message, as_report)
from aerodaas.recording.reader import summarize_mcap

__all__ = ["ACCOUNTING_TOPIC", "ANALYTICS_OUTPUT_SUFFIXES", "ChannelAccount", "accounting_message",
           "account_channels", "account_recording", "as_report"]


def account_recording(paths: list[str | os.PathLike]) -> dict[str, Any] | None:
    """The accounting of a run recorded in ``paths`` (its segments in order, or the one file): ``{"channels":
    {topic: {produced, duplicates, recorded, lost}}, "lost": {topic: n} (only channels that lost any),
    "lost_total": n, "tasks": {scheduler: {tasks, states, tiers, on_time, utility, cost, cost_by_tier}}}``, with
    each channel's messages counted over every segment and the producers' counts and the analytics schedulers'
    task records (:mod:`aerodaas.recording.task_tally`; ``{}`` without any) from the last ``/run/accounting``; None
    when no segment has one (a recording made before accounting, or cut short before its end). Raises what
    :func:`aerodaas.recording.reader.summarize_mcap` raises."""
    counts: dict[str, int] = {}
    accounting = None
    for p in paths:
        s = summarize_mcap(p)
        for c in s["channels"]:
            counts[c["topic"]] = counts.get(c["topic"], 0) + c["count"]
        accounting = s.get("accounting_message") or accounting
    chans = account_channels(accounting, counts)
    if chans is None:
        return None
    tasks = accounting.get("tasks")
    return {**as_report(chans), "tasks": dict(tasks) if isinstance(tasks, dict) else {}}
