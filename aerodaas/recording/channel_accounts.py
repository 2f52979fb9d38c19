"""End-to-end accounting of a recording: what each channel lost, derived from the file (the arithmetic;
:func:`aerodaas.recording.accounting.account_recording` applies it to a recorded run's files).

Every message a producer actor offers the recorder is numbered on its stream (its topic): 0, 1, 2 ... per producer,
the messages it dropped itself included, the numbering continued across the producer's restarts (the recorder
actor keeps each producer's count, :class:`~aerodaas.protocol.messages.ProducerLedger`). The number is the MCAP
message's ``sequence`` (readable by any MCAP reader), and the recording's last message, ``/run/accounting``
(:class:`~aerodaas.recording.schemas.RunAccounting`), holds per stream how many its producers numbered and how
many were deliberately not recorded (sent again by a restarted drone actor). A channel's loss is then

    lost = produced - duplicates - messages on the channel in the recording (every segment of the run)

whatever the cause: a recorder that stalled or died, a full queue, a producer killed between its batches, a
batch that never arrived. What is not knowable: the messages a producer numbered after its last batch reached the
recorder actor when it was killed (at most one batching period, 0.1 s, of that actor's messages) and everything
numbered while the recorder actor itself was dead and before the producer's next batch (the producer's next batch
carries its whole count again, so only a producer killed in that window goes uncounted).

An analytics' outputs are accounted against its inputs: every actor counts the items it hands each analytics
(per robot), and each analytics the items it takes without recording an output (``process`` returned None,
raised, a stale item, a task its scheduler did not run on time); what it was offered less those is what its output
topics must hold. So an analytics killed twice (its restarts used up) loses, on its output channel, every item
its senders offered it afterwards and every one in flight at the kills.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

__all__ = ["ACCOUNTING_TOPIC", "ANALYTICS_OUTPUT_SUFFIXES", "ChannelAccount", "accounting_message",
           "account_channels", "as_report"]

ACCOUNTING_TOPIC = "/run/accounting"
"""JSON topic of the recording's accounting (:class:`~aerodaas.recording.schemas.RunAccounting`)."""


@dataclass(frozen=True)
class ChannelAccount:
    """One channel's accounting (messages): ``produced`` numbered by its producers, ``duplicates`` deliberately
    not recorded, ``recorded`` in the recording, ``lost`` = produced - duplicates - recorded (never below 0)."""

    produced: int
    duplicates: int
    recorded: int
    lost: int


def accounting_message(ledgers: list[Any], duplicates: dict[str, int]) -> dict[str, Any]:
    """The ``/run/accounting`` message (:class:`~aerodaas.recording.schemas.RunAccounting`) of producers'
    ``ledgers`` (:class:`~aerodaas.protocol.messages.ProducerLedger`, one per producer actor) and the messages the
    recorder dropped as sent again (topic -> n): ``{"channels": {topic: {produced, duplicates}}, "analytics":
    {"/<robot>/<name>": {offered, no_output}}}`` (an analytics' items offered by every sender, and those it took
    without recording an output; only analytics whose name a ledger gives)."""
    produced: dict[str, int] = {}
    offered: dict[str, dict[str, int]] = {}
    without: dict[str, dict[str, int]] = {}
    names: dict[str, str] = {}
    for led in ledgers:
        for topic, n in led.produced.items():
            produced[topic] = produced.get(topic, 0) + n
        for into, src in ((offered, led.offered_to), (without, led.no_output)):
            for cid, per in src.items():
                mine = into.setdefault(cid, {})
                for robot, n in per.items():
                    mine[robot] = mine.get(robot, 0) + n
        names.update(led.analytics)
    analytics: dict[str, dict[str, int]] = {}
    for cid, name in names.items():
        for robot in {*offered.get(cid, {}), *without.get(cid, {})}:
            a = analytics.setdefault(f"/{robot}/{name}", {"offered": 0, "no_output": 0})
            a["offered"] += offered.get(cid, {}).get(robot, 0)
            a["no_output"] += without.get(cid, {}).get(robot, 0)
    return {"channels": {t: {"produced": n, "duplicates": duplicates.get(t, 0)} for t, n in sorted(produced.items())},
            "analytics": dict(sorted(analytics.items()))}


#: the topics an analytics ``/<robot>/<name>`` records its outputs on (detections, navigation, anything else)
ANALYTICS_OUTPUT_SUFFIXES = ("/detections", "/navigation", "")


def account_channels(accounting: Any, counts: dict[str, int]) -> dict[str, ChannelAccount] | None:
    """Per channel accounting from a ``/run/accounting`` message (its decoded JSON; None or malformed: None) and
    ``counts`` (topic -> messages in the recording). An analytics' outputs are one account, on the first of its
    output topics (:data:`ANALYTICS_OUTPUT_SUFFIXES`) that exists: expected are the items it was offered less those
    it took without an output (or, if more, what it numbered itself), recorded its messages on all of them."""
    chans = accounting.get("channels") if isinstance(accounting, dict) else None
    if not isinstance(chans, dict):
        return None
    out = {}
    for topic, c in sorted(chans.items()):
        if not isinstance(c, dict):
            continue
        produced, dup = int(c.get("produced", 0)), int(c.get("duplicates", 0))
        rec = int(counts.get(topic, 0))
        out[topic] = ChannelAccount(produced, dup, rec, max(0, produced - dup - rec))
    for prefix, a in sorted((accounting.get("analytics") or {}).items()):
        topics = [prefix + sfx for sfx in ANALYTICS_OUTPUT_SUFFIXES]
        target = next((t for t in topics if t in out or counts.get(t)), prefix)
        own = sum(out.pop(t).produced for t in topics if t in out)
        produced = max(own, int(a.get("offered", 0)) - int(a.get("no_output", 0)))
        rec = sum(int(counts.get(t, 0)) for t in topics)
        out[target] = ChannelAccount(produced, 0, rec, max(0, produced - rec))
    return dict(sorted(out.items()))


def as_report(chans: dict[str, ChannelAccount]) -> dict[str, Any]:
    """The JSON form of per-channel accounts (see :func:`aerodaas.recording.accounting.account_recording`)."""
    lost = {t: c.lost for t, c in chans.items() if c.lost}
    return {"channels": {t: asdict(c) for t, c in chans.items()}, "lost": lost, "lost_total": sum(lost.values())}
