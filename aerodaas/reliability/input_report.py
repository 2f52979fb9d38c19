"""The input half of ``docs/reliability.md``: each case run under a guard (an exception other than the documented
refusal is a *traceback*, a case that does not end within its time limit a *hang*), the rows grouped by category,
and the Markdown tables (:func:`render_inputs`, :func:`render_input_rows`). Used by
:mod:`aerodaas.reliability.catalogue`."""
from __future__ import annotations

import re
import signal
import threading
import traceback
from typing import Any, Callable

__all__ = ["CATEGORIES", "KIND_CATEGORY", "guarded", "summarize", "render_inputs", "render_input_rows"]

#: the report's categories, in its order
CATEGORIES = ("ids", "strict types", "bounds / cross-field", "unknown keys", "geofence", "files and images",
              "HITL settings", "plug-in imports", "output paths", "mission files", "safety gate", "command line",
              "app-level errors", "HITL API")

#: the category of a row that does not name its own, by its kind
KIND_CATEGORY = {"--record path": "output paths", "JSON file": "files and images", "mission upload": "mission files",
                 "mission file": "mission files", "safety gate": "safety gate", "command line": "command line",
                 "application error": "app-level errors", "HITL API": "HITL API"}


class _Hang(Exception):
    """Raised into a case that did not end within its time limit (SIGALRM)."""


def guarded(run: Callable[[], list[dict[str, Any]]], kind: str, name: str, category: str,
            timeout_s: float) -> list[dict[str, Any]]:
    """``run()``'s rows, each with a ``category`` (its own, or :data:`KIND_CATEGORY` of its kind, or ``category``)
    and ``traceback`` / ``hang`` flags. An exception ``run`` lets out is one row (``kind``, ``name``) refused=False
    with traceback=True; no answer within ``timeout_s`` seconds one row with hang=True. ``run`` runs in this thread
    (``aerodaas run`` installs signal handlers, which only the main thread may): the limit is a SIGALRM timer
    (``signal.setitimer``), none off the main thread."""
    timed = threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer")

    def on_alarm(signum: int, frame: Any) -> None:
        raise _Hang()

    old = signal.signal(signal.SIGALRM, on_alarm) if timed else None
    try:
        if timed:
            signal.setitimer(signal.ITIMER_REAL, timeout_s)
        try:
            rows = run()
        finally:
            if timed:
                signal.setitimer(signal.ITIMER_REAL, 0)
    except _Hang:
        return [{"kind": kind, "category": category, "name": name, "refused": False, "traceback": False,
                 "hang": True, "message": f"no answer within {timeout_s:g} s"}]
    except Exception as e:  # noqa: BLE001 - reported as a row: an exception that escaped is the finding
        err = "".join(traceback.format_exception_only(type(e), e)).strip()
        return [{"kind": kind, "category": category, "name": name, "refused": False, "traceback": True,
                 "hang": False, "message": f"raised {err}"}]
    finally:
        if timed:
            signal.signal(signal.SIGALRM, old)
    for r in rows:
        r.setdefault("category", KIND_CATEGORY.get(r["kind"], category))
        r.setdefault("traceback", "Traceback (most recent call last)" in r["message"] and
                     r["kind"] != "application error")
        r.setdefault("hang", False)
    return rows


def summarize(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The counts of ``rows``: tried, refused (as documented), accepted wrongly (names), tracebacks, hangs."""
    return {"rows": rows, "tried": len(rows), "refused": sum(bool(r["refused"]) for r in rows),
            "accepted_wrongly": [r["name"] for r in rows if not r["refused"]],
            "tracebacks": [r["name"] for r in rows if r.get("traceback")],
            "hangs": [r["name"] for r in rows if r.get("hang")]}


def _first_line(message: str) -> str:
    lines = [ln.strip() for ln in message.splitlines() if ln.strip()]
    if not lines:
        return ""
    if lines[0].startswith("invalid environment") and len(lines) > 1:
        return lines[1]
    if re.search(r"\d+ validation errors? for \w+$", lines[0]) and len(lines) > 2:  # pydantic: the field and why
        return f"{lines[0]}: {lines[1]}: {lines[2].split(' [type=')[0]}"
    return lines[0]


def render_inputs(inputs: dict[str, Any]) -> list[str]:
    """Markdown lines: the totals, one row per category, then every case grouped by category."""
    rows = inputs["rows"]
    order = {c: i for i, c in enumerate(CATEGORIES)}
    cats = sorted({r["category"] for r in rows}, key=lambda c: (order.get(c, len(order)), c))
    lines = ["| inputs tried | refused / answered as documented | accepted wrongly | tracebacks | hangs |",
             "|---|---|---|---|---|",
             f"| {inputs['tried']} | {inputs['refused']} | {len(inputs['accepted_wrongly'])} | "
             f"{len(inputs['tracebacks'])} | {len(inputs['hangs'])} |", "",
             "| category | inputs tried | refused / answered as documented | accepted wrongly | tracebacks | hangs |",
             "|---|---|---|---|---|---|"]
    for c in cats:
        rs = [r for r in rows if r["category"] == c]
        lines.append(f"| {c} | {len(rs)} | {sum(bool(r['refused']) for r in rs)} | "
                     f"{sum(not r['refused'] for r in rs)} | {sum(bool(r.get('traceback')) for r in rs)} | "
                     f"{sum(bool(r.get('hang')) for r in rs)} |")
    lines.append("")
    return lines


def render_input_rows(inputs: dict[str, Any]) -> list[str]:
    """Markdown lines of the per-case table, grouped by category."""
    rows = inputs["rows"]
    order = {c: i for i, c in enumerate(CATEGORIES)}
    rows = sorted(rows, key=lambda r: order.get(r["category"], len(order)))  # stable: the catalogue's order within
    lines = ["| category | kind | input | refused / answered as documented | error (first line) |",
             "|---|---|---|---|---|"]
    for r in rows:
        ok = "yes" if r["refused"] else "**NO**" + (" (traceback)" if r.get("traceback") else "") + \
            (" (hang)" if r.get("hang") else "")
        lines.append(f"| {r['category']} | {r['kind']} | {r['name']} | {ok} | "
                     f"`{_first_line(r['message'])[:160].replace('|', '/')}` |")
    return lines
