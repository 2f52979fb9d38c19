"""Reading a mission file of either format, detected from its content (:func:`load_mission`)."""
from __future__ import annotations

from pathlib import Path

from aerodaas.missionfile._common import _fail, _read_text
from aerodaas.missionfile.plans import MissionPlan
from aerodaas.missionfile.qgc_plan import _parse_plan
from aerodaas.missionfile.wpl import _parse_wpl


def load_mission(path: str | Path) -> MissionPlan:
    """Read a mission file of either format, detected from its content: JSON (``{``) is a QGroundControl
    ``.plan``, a first line ``QGC WPL ...`` is a waypoint file. Raises :class:`MissionFileError` otherwise."""
    path = Path(path)
    text = _read_text(path)
    head = text.lstrip()
    if head.startswith("{"):
        return _parse_plan(text, str(path))
    if head.startswith("QGC WPL"):
        return _parse_wpl(text, str(path))
    first = head.splitlines()[0] if head else ""
    raise _fail(str(path), "line 1", f"not a QGroundControl .plan (JSON) nor a 'QGC WPL 110' file: {first!r:.80}")
