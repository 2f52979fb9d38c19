"""``QGC WPL 110`` waypoint files (Mission Planner, ArduPilot, MAVSDK, QGroundControl export; the MAVLink
plain-text mission format, mavlink.io ``file_formats``): :func:`load_wpl`, :func:`save_wpl` and :func:`wpl_text`."""
from __future__ import annotations

import math
from decimal import Decimal
from pathlib import Path

from aerodaas.model.types import GeoPoint
from aerodaas.missionfile._common import _fail, _read_text
from aerodaas.missionfile.commands import (_AMSL_FRAMES, MAV_CMD_DO_JUMP, MAV_CMD_NAV_WAYPOINT, MAV_FRAME_GLOBAL, frame_name,
                       command_name)
from aerodaas.missionfile.expand import expand_items
from aerodaas.missionfile.items import MissionItem, _check_command_frame, _check_position
from aerodaas.missionfile.plans import MissionPlan


_WPL_FIELDS = ("seq", "current", "frame", "command", "param1", "param2", "param3", "param4",
               "x (latitude)", "y (longitude)", "z (altitude)", "autocontinue")


def _parse_wpl(text: str, src: str) -> MissionPlan:
    lines = text.splitlines()
    if not lines:
        raise _fail(src, "line 1", "empty file; expected the header 'QGC WPL 110'")
    header = lines[0].strip()
    parts = header.split()
    if len(parts) != 3 or parts[0] != "QGC" or parts[1] != "WPL" or parts[2] not in ("110", "120"):
        raise _fail(src, "line 1", f"expected the header 'QGC WPL 110', got {header!r:.80}")
    home_row_allowed = parts[2] == "110"  # QGroundControl: 110 = ArduPilot file with home in row 0; 120 = no home

    rows: list[tuple[int, MissionItem, int]] = []  # (line, item, seq in the file)
    for lineno, line in enumerate(lines[1:], start=2):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        where = f"line {lineno}"
        fields = s.split()
        if len(fields) != 12:
            raise _fail(src, where, f"expected 12 tab-separated fields ({' '.join(_WPL_FIELDS)}), got "
                                    f"{len(fields)}: {s!r:.120}")
        ints: dict[int, int] = {}
        for i in (0, 1, 2, 3, 11):
            try:
                ints[i] = int(fields[i])
            except ValueError:
                raise _fail(src, where, f"{_WPL_FIELDS[i]} must be an integer, got {fields[i]!r}") from None
        for i in (1, 11):
            if ints[i] not in (0, 1):
                raise _fail(src, where, f"{_WPL_FIELDS[i]} must be 0 or 1, got {fields[i]!r}")
        if ints[0] < 0:
            raise _fail(src, where, f"seq must be >= 0, got {fields[0]!r}")
        command, frame = ints[3], ints[2]
        _check_command_frame(src, where, command, frame)
        where = f"{where} ({command_name(command)})"
        params: list[float | None] = []
        for i in range(4, 11):
            try:
                v = float(fields[i])
            except ValueError:
                raise _fail(src, where, f"{_WPL_FIELDS[i]} must be a number, got {fields[i]!r}") from None
            if math.isinf(v):
                raise _fail(src, where, f"{_WPL_FIELDS[i]} must be finite, got {fields[i]!r}")
            params.append(None if math.isnan(v) else v)
        _check_position(src, where, frame, params)
        expected = rows[-1][2] + 1 if rows else None
        if expected is None and ints[0] > 1:
            raise _fail(src, where, f"seq must start at 0 (the home row) or 1, got {ints[0]}")
        if expected is not None and ints[0] != expected:  # DO_JUMP targets name seq numbers: never renumbered
            raise _fail(src, where, f"seq {ints[0]} out of order: the row after seq {expected - 1} must be seq "
                                    f"{expected} (rows are numbered consecutively; DO_JUMP targets refer to them)")
        rows.append((lineno, MissionItem(seq=0, command=command, frame=frame, params=params,
                                         autocontinue=bool(ints[11])), ints[0]))

    home = None
    home_row = bool(rows) and home_row_allowed and rows[0][1].command == MAV_CMD_NAV_WAYPOINT
    if home_row:
        lineno, h, _ = rows.pop(0)
        lat, lon, alt = h.params[4], h.params[5], h.params[6]
        if not (lat in (None, 0.0) and lon in (None, 0.0)):  # all-zero row = home not set (Mission Planner)
            if h.frame not in _AMSL_FRAMES:
                raise _fail(src, f"line {lineno} (home position)",
                            f"the home row must be in MAV_FRAME_GLOBAL (0) with an AMSL altitude, got "
                            f"{frame_name(h.frame)}")
            if lat is None or lon is None or alt is None:
                raise _fail(src, f"line {lineno} (home position)", f"latitude/longitude/altitude must be set, "
                                                                   f"got {lat!r}, {lon!r}, {alt!r}")
            home = GeoPoint(lat=lat, lon=lon, alt=alt)
    items = []
    for k, (_, item, _) in enumerate(rows):
        params = list(item.params)
        if not home_row and item.command == MAV_CMD_DO_JUMP and params[0] is not None:
            params[0] += 1  # DO_JUMP targets in a file without home row count from 0; ours count home as 0
        items.append(item.model_copy(update={"seq": k + 1, "params": params}))
    return MissionPlan(home=home, items=items, source=src)


def load_wpl(path: str | Path) -> MissionPlan:
    """Read a ``QGC WPL 110`` waypoint file (Mission Planner, ArduPilot, MAVSDK, QGroundControl export): a header
    line, then one tab-separated row per item ``seq current frame command param1 param2 param3 param4 x y z
    autocontinue``; CRLF or LF line ends, blank and ``#`` lines ignored.

    Row 0 is the home position when it is a ``MAV_CMD_NAV_WAYPOINT`` (the ArduPilot / Mission Planner /
    QGroundControl convention; an all-zero home row means "home not set"). A file whose first row is another
    command (MAVSDK's PX4 sample starts with ``MAV_CMD_NAV_TAKEOFF``), or a ``QGC WPL 120`` file, has no home row:
    every row is a mission item and ``MAV_CMD_DO_JUMP`` targets are shifted by one, as QGroundControl does.
    The rows' ``seq`` must count up by one from 0 or 1 (a file numbered 1, 1, 5 was renumbered silently, and its
    DO_JUMP targets with it). Items are numbered 1..n (``seq``) in file order. Raises :class:`MissionFileError` naming the file, line and
    value for a wrong header, a malformed row, a row out of sequence, an unknown frame or an out-of-range
    latitude/longitude."""
    path = Path(path)
    return _parse_wpl(_read_text(path), str(path))


def _wpl_number(v: float | None) -> str:
    if v is None:
        return "NaN"
    if float(v).is_integer() and abs(v) < 2 ** 53:
        return str(int(v))
    s = repr(float(v))
    return format(Decimal(s), "f") if "e" in s or "E" in s else s


def wpl_text(plan: MissionPlan) -> str:
    """The ``QGC WPL 110`` text for ``plan`` (what :func:`save_wpl` writes)."""
    items = expand_items(plan)
    home_row = plan.home is not None or (bool(items) and items[0].command == MAV_CMD_NAV_WAYPOINT)
    lines = ["QGC WPL 110"]
    if home_row:
        h = plan.home
        hp = [0.0, 0.0, 0.0, 0.0] + ([h.lat, h.lon, h.alt] if h is not None else [0.0, 0.0, 0.0])
        lines.append("\t".join(["0", "1", str(MAV_FRAME_GLOBAL), str(MAV_CMD_NAV_WAYPOINT)]
                               + [_wpl_number(p) for p in hp] + ["1"]))
    for k, item in enumerate(items):
        params = list(item.params)
        if not home_row and item.command == MAV_CMD_DO_JUMP and params[0] is not None:
            params[0] -= 1
        seq = k + 1 if home_row else k
        current = 1 if (not home_row and k == 0) else 0
        lines.append("\t".join([str(seq), str(current), str(item.frame), str(item.command)]
                               + [_wpl_number(p) for p in params] + [str(int(item.autocontinue))]))
    return "\n".join(lines) + "\n"


def save_wpl(plan: MissionPlan, path: str | Path) -> None:
    """Write ``plan`` as a ``QGC WPL 110`` file (tab-separated, LF line ends, NaN for unset params).

    Row 0 is the home position (``MAV_FRAME_GLOBAL``, AMSL) when ``plan.home`` is set; without a home, a
    placeholder all-zero home row is written if the first item is a ``MAV_CMD_NAV_WAYPOINT`` (so it is not
    mistaken for home on reading), otherwise the items start at row 0 (PX4 / MAVSDK style). ComplexItems are
    expanded (WPL has no complex items); one that cannot be expanded raises :class:`MissionFileError`. The
    geofence and rally points cannot be stored in WPL and are not written."""
    Path(path).write_text(wpl_text(plan), encoding="utf-8")
