"""One grammar for every id a user gives: robots, sensors, compute resources, world targets, analytics names and
plug-in names.

An id is 1-64 ASCII characters: a letter first, then letters, digits, ``_`` or ``-`` (``ID_PATTERN``). It becomes
part of Ray actor names, MCAP topics (``/<robot>/camera/<sensor>``, ``/<robot>/<analytics>/detections``), file names
and log lines, so nothing in it may separate, hide or look like something else: no ``/`` (a topic separator), no
``#`` (component instance numbers), no blanks, control or format characters (a newline, NUL, a right-to-left
override, a zero-width space), no non-ASCII letters (look-alike twins, NFC/NFD spellings). A plug-in's registered
name, which names no topic, may also hold ``+`` and ``.`` (:data:`PLUGIN_NAME_PATTERN`: the paper's ``E+C``). Ids
of one kind are unique case-insensitively (``d1`` and ``D1`` are one robot to a reader of the logs). A name under a robot's topics
(an analytics, a plug-in sensor) may not be one of the segments AeroDaaS itself records there (:data:`RESERVED`):
a sensor plug-in called ``odometry`` would share the robot's odometry channel.

Together these make every component's topics distinct (the property ``tests/inputs/test_ids.py`` checks with hypothesis:
every topic an accepted environment records has one owner).
"""
from __future__ import annotations

import re
import unicodedata
from typing import Annotated, Iterable

from pydantic import AfterValidator

__all__ = ["ID_PATTERN", "MAX_ID_LENGTH", "PLUGIN_NAME_PATTERN", "RESERVED", "ROOT_RESERVED", "Identifier", "RobotId",
           "check_analytics_names", "check_id", "check_plugin_name", "check_robot_id", "check_topic_name",
           "check_unique"]

MAX_ID_LENGTH = 64
ID_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,63}")
#: a plug-in's registered name (what ``environment.json`` and the CLI type, never a topic): the id grammar plus ``+``
#: and ``.`` (the paper's ``E+C`` policy); no ``:`` (``module.path:ClassName`` references), ``/``, ``#`` or blanks
PLUGIN_NAME_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_+.-]{0,63}")
#: the topic segments AeroDaaS records under ``/<robot>/`` itself (aerodaas.recording, actors): an analytics or a
#: plug-in sensor named like one of them would share its channel
RESERVED = frozenset({"camera", "events", "pose", "odometry", "gps", "nav", "mission", "latency"})
#: the top-level topics that are not a robot's (``/mission/state``, ``/run/result``, ``/world/...``, ``/tracks/scene``):
#: no robot may be called like them
ROOT_RESERVED = frozenset({"mission", "run", "world", "tracks", "tf", "scene", "env"})


def _describe(value: str) -> str:
    """``value`` with each character a reader cannot see named (U+202E RIGHT-TO-LEFT OVERRIDE, U+0000 ...)."""
    odd = [f"U+{ord(c):04X} {unicodedata.name(c, 'unnamed')}" for c in value
           if not (c.isascii() and c.isprintable()) or c.isspace()]
    return f"{value!r}" + (f" (contains {', '.join(dict.fromkeys(odd))})" if odd else "")


def check_id(value: str, what: str = "id") -> str:
    """``value`` if it is a valid id (see the module docstring), else ValueError naming ``what`` (e.g. ``robot id``),
    the value with its invisible characters spelled out, and the grammar."""
    if not isinstance(value, str):
        raise ValueError(f"{what} must be a string, got {type(value).__name__} {value!r}")
    if ID_PATTERN.fullmatch(value) is None:
        why = (f"longer than {MAX_ID_LENGTH} characters" if len(value) > MAX_ID_LENGTH else
               "empty" if not value else "not of the id grammar")
        raise ValueError(f"{what} {_describe(value[:100])} is {why}: an id is 1-{MAX_ID_LENGTH} ASCII letters, "
                         f"digits, '_' or '-', starting with a letter (it names topics, actors and files)")
    return value


def check_plugin_name(value: str, what: str = "plug-in name") -> str:
    """``value`` if it is a valid plug-in name (:data:`PLUGIN_NAME_PATTERN`), else ValueError naming ``what`` and
    the value with its invisible characters spelled out."""
    if not isinstance(value, str) or PLUGIN_NAME_PATTERN.fullmatch(value) is None:
        raise ValueError(f"{what} {_describe(str(value)[:100])} is not of the plug-in name grammar: 1-{MAX_ID_LENGTH} "
                         f"ASCII letters, digits, '_', '-', '+' or '.', starting with a letter")
    return value


def check_topic_name(value: str, what: str) -> str:
    """:func:`check_id`, and not one of the :data:`RESERVED` segments (case-insensitively). Raises ValueError."""
    check_id(value, what)
    if value.lower() in RESERVED:
        raise ValueError(f"{what} {value!r} is a name AeroDaaS records under each robot itself "
                         f"({', '.join(sorted(RESERVED))}): its topics would be shared; choose another")
    return value


def check_robot_id(value: str, what: str = "robot id") -> str:
    """:func:`check_id`, and not one of the :data:`ROOT_RESERVED` top-level topic names. Raises ValueError."""
    check_id(value, what)
    if value.lower() in ROOT_RESERVED:
        raise ValueError(f"{what} {value!r} is a top-level topic of every recording ({', '.join(sorted(ROOT_RESERVED))})"
                         f": its topics would be shared; choose another")
    return value


def check_unique(ids: Iterable[str], what: str) -> None:
    """Raises ValueError when two of ``ids`` are equal after case-folding (``d1``/``D1``), naming them and ``what``
    (e.g. ``robots``)."""
    seen: dict[str, str] = {}
    for i in ids:
        key = unicodedata.normalize("NFC", i).casefold()
        if key in seen:
            if seen[key] == i:
                raise ValueError(f"{what}: duplicate ids [{i!r}]")
            raise ValueError(f"{what}: duplicate ids [{seen[key]!r}, {i!r}]: the same id but for case (a reader of "
                             f"topics and logs cannot tell them apart)")
        seen[key] = i


def check_analytics_names(robot: str, names: list[tuple[str, str]], sensors: list[str]) -> None:
    """The analytics of robot ``robot``: ``names`` as (name, class name). Each name is a topic name
    (:func:`check_topic_name`), unique among them and distinct from every sensor id of the robot (``sensors``; a
    plug-in sensor records on ``/<robot>/<id>``, an analytics on ``/<robot>/<name>``), all case-insensitively.
    Raises ValueError naming the robot and the names."""
    for name, cls in names:
        check_topic_name(name, f"robot {robot!r}: analytics name ({cls})")
    check_unique([n for n, _ in names], f"robot {robot!r}: the analytics' names (name=...)")
    taken = {s.casefold(): s for s in sensors}
    for name, cls in names:
        if name.casefold() in taken:
            raise ValueError(f"robot {robot!r}: analytics name ({cls}) {name!r} is the id of its sensor "
                             f"{taken[name.casefold()]!r}")


#: a pydantic field type: ``id: Identifier``
Identifier = Annotated[str, AfterValidator(check_id)]
#: a pydantic field type for a robot's id
RobotId = Annotated[str, AfterValidator(check_robot_id)]
