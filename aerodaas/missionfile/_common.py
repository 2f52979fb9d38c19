"""What the mission-file modules share: :class:`MissionFileError` and the helpers that build its messages (file,
item or line, offending value), read a file as UTF-8 text and test for a JSON number."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import ValidationError


class MissionFileError(ValueError):
    """A mission file or plan that cannot be read, written or flown. The message names the file, the line or
    item (sequence number, command number and name) and the offending value."""


def _fail(src: str, where: str, msg: str) -> MissionFileError:
    return MissionFileError(f"{src}: {where}: {msg}")


def _read_text(path: Path) -> str:
    try:
        data = path.read_bytes()
    except OSError as e:
        raise MissionFileError(f"{path}: cannot read mission file ({e.strerror or e})") from e
    from aerodaas.model.jsonfile import JsonFileError, decode_text  # lazy: heavy numpy

    try:
        return decode_text(data, str(path))
    except JsonFileError as e:
        raise MissionFileError(str(e)) from None


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _first_error(e: ValidationError) -> str:
    err = e.errors()[0]
    loc = ".".join(str(x) for x in err.get("loc", ()))
    return f"{loc}: {err['msg']} (got {err.get('input')!r})" if loc else f"{err['msg']} (got {err.get('input')!r})"
