"""The end of a run's actors: each closed in order (analytics and dispatchers, drones, the recorder last, so that
everything they recorded reaches the file), and a recording whose recorder actor died while closing finished here."""
from __future__ import annotations

import os
import sys

from aerodaas.recording.recover import recover_mcap
from aerodaas.runtime.node_recorders import close_node_recorders, node_recorder_ids
from aerodaas.runtime.supervise import error_cause as _cause

__all__ = ["close_actors"]


def close_actors(actors: dict, record: str | None) -> tuple[dict, dict]:
    """Close every actor (analytics and dispatchers first, drones, the recorder last: everything they recorded
    reaches the file); returns (message counts, recording report). Never raises."""
    import ray  # lazy: heavy ray

    nodes = node_recorder_ids(actors)
    order = sorted((h for h in actors if h != "recorder" and h not in nodes), key=lambda h: h.startswith("drone"))
    pings = {hid: actors[hid].ping.remote() for hid in order}
    alive = set()
    for hid, ref in pings.items():  # an actor whose node is gone (pending a restart that cannot happen) is skipped
        try:
            ray.get(ref, timeout=10)
            alive.add(hid)
        except Exception:  # noqa: BLE001
            print(f"aerodaas: warning: actor {hid!r} is gone (not closed; the recording has what it sent)",
                  file=sys.stderr)
    order = [h for h in order if h in alive]
    refs = {}
    for hid in order:
        try:
            refs[hid] = actors[hid].close.remote()
        except Exception:  # noqa: BLE001
            pass
    for hid, ref in refs.items():
        try:
            ray.get(ref, timeout=60)
        except Exception as e:  # noqa: BLE001 - a dead actor has nothing left to close
            if not isinstance(e, ray.exceptions.RayActorError):
                print(f"aerodaas: warning: actor {hid!r} could not be closed cleanly: {_cause(e)}", file=sys.stderr)
    node_reports = close_node_recorders(actors) if nodes else {}  # after their producers, before the driver's
    counts: dict = {}
    rep: dict = {}
    if "recorder" in actors:
        try:
            counts = ray.get(actors["recorder"].close.remote(), timeout=120)
            rep = ray.get(actors["recorder"].recording_report.remote(), timeout=60)
        except ray.exceptions.RayActorError as e:  # it died while closing (its node with it): finish it here
            loss = {"segment": record, "recorded_until_ns": None, "previous_finished": False,
                    "error": f"the recorder actor died while closing: {_cause(e)}"}
            rep = {"losses": [loss]}
            counts = _finish_orphaned_recording(record, loss)
            how = f"finished it here: {sum(counts.values())} messages" if loss["previous_finished"] else \
                f"run `aerodaas recover {record}`"
            print(f"aerodaas: warning: the recorder actor died while closing the recording {record} ({how})",
                  file=sys.stderr)
        except Exception as e:  # noqa: BLE001 - pragma: no cover - reported, never silently lost
            print(f"aerodaas: warning: the recorder could not be closed cleanly (recording: {record}): {_cause(e)}",
                  file=sys.stderr)
    if node_reports:  # one recorder per node: their files, and their losses are the run's
        rep["nodes"] = node_reports
        rep["losses"] = [*(rep.get("losses") or []), *(x for r in node_reports.values() for x in r.get("losses") or []),
                         *({"segment": h, "error": r["error"]} for h, r in node_reports.items() if "error" in r)]
    return counts, rep


def _finish_orphaned_recording(record: str | None, loss: dict) -> dict[str, int]:
    """The recording of a recorder actor that died with its node, finished by the driver when the file is on this
    machine (local mode, `aerodaas up`): rewritten as a finished MCAP (:func:`aerodaas.recording.recover.
    recover_mcap`, what ``aerodaas recover`` does), ``loss`` updated with ``recorded_until_ns`` and
    ``previous_finished``. Returns the per-topic message counts it holds ({} when the file is not here or cannot
    be read; then ``loss["finish_error"]`` says why)."""
    if not record or not os.path.isfile(record):
        return {}
    from aerodaas.recording.reader import summarize_mcap  # lazy: heavy mcap

    try:
        recover_mcap(record)
        summary = summarize_mcap(record)
    except (OSError, ValueError) as e:
        loss["finish_error"] = f"{type(e).__name__}: {e}"
        return {}
    loss["recorded_until_ns"] = summary.get("end_ns")
    loss["previous_finished"] = True
    return {c["topic"]: c["count"] for c in summary.get("channels", [])}
