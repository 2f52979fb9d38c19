"""A bounded JSON reader for every file a user hands AeroDaaS (environment, ``.plan``, geofence plan, workload):
size and nesting depth limited before parsing (a 100,000-deep nesting overflowed Python's recursion as a raw
``RecursionError``), text other than UTF-8 named (UTF-16/32 by their byte-order mark or NUL pattern, else the first
bad byte and its line), duplicate object keys refused (RFC 8259 §4: names *should* be unique, and Python's ``json``
silently keeps the last one), integers limited to :data:`MAX_INT_DIGITS` digits. Every error is a
:class:`JsonFileError` (a ``ValueError``) naming the file and the line. Linear time in the file's size."""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["JsonFileError", "MAX_JSON_BYTES", "MAX_JSON_DEPTH", "MAX_INT_DIGITS", "decode_text", "parse_json",
           "read_json"]

#: largest JSON file read (bytes): a 100k-item mission is ~ 40 MB
MAX_JSON_BYTES = 256 * 1024 * 1024
#: deepest nesting of arrays/objects (the deepest real document, a .plan's geofence, is 6 deep)
MAX_JSON_DEPTH = 64
#: longest integer literal (digits): every number AeroDaaS reads is far shorter
MAX_INT_DIGITS = 30

_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"')


class JsonFileError(ValueError):
    """A JSON file that cannot be read: the message names the file, the line and the reason."""


def _line(text: str, index: int) -> int:
    return text.count("\n", 0, index) + 1


def decode_text(data: bytes, src: str) -> str:
    """``data`` as UTF-8 text (a UTF-8 byte-order mark is dropped). Raises :class:`JsonFileError` naming the
    encoding (UTF-16/UTF-32 by their byte-order mark or NUL bytes) or the first byte that is not UTF-8 and its line."""
    for bom, name in ((b"\xff\xfe\x00\x00", "UTF-32-LE"), (b"\x00\x00\xfe\xff", "UTF-32-BE"),
                      (b"\xff\xfe", "UTF-16-LE"), (b"\xfe\xff", "UTF-16-BE")):
        if data.startswith(bom):
            raise JsonFileError(f"{src}: the file is {name} text (byte-order mark); save it as UTF-8")
    if len(data) >= 4 and b"\x00" in data[:4]:
        raise JsonFileError(f"{src}: the file looks like UTF-16 or UTF-32 text (NUL bytes); save it as UTF-8")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise JsonFileError(f"{src}: line {line}: not UTF-8 text (byte {e.start}: {data[e.start:e.start + 1]!r}; "
                            f"Latin-1 or Windows-1252?); save it as UTF-8") from None


def _check_depth(text: str, src: str, max_depth: int) -> None:
    blank = _STRING.sub(lambda m: '""'.ljust(len(m.group()), " "), text)  # same offsets, no brackets in strings
    a = np.frombuffer(blank.encode("utf-32-le"), dtype=np.uint32)
    step = np.zeros(a.shape, dtype=np.int32)
    step[(a == ord("[")) | (a == ord("{"))] = 1
    step[(a == ord("]")) | (a == ord("}"))] = -1
    depth = np.cumsum(step)
    deep = np.flatnonzero(depth > max_depth)
    if deep.size:
        raise JsonFileError(f"{src}: line {_line(text, int(deep[0]))}: JSON nested deeper than {max_depth} levels")


def parse_json(text: str, src: str, max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Parse JSON ``text`` (from ``src``, for messages) with the depth, duplicate-key and integer limits.
    Raises :class:`JsonFileError` naming ``src`` and the line."""
    _check_depth(text, src, max_depth)

    def pairs(items: list[tuple[str, Any]]) -> dict:
        out: dict = {}
        for k, v in items:
            if k in out:
                raise JsonFileError(f"duplicate key {k!r}")
            out[k] = v
        return out

    def big_int(s: str) -> int:
        if len(s.lstrip("-")) > MAX_INT_DIGITS:
            raise JsonFileError(f"an integer of {len(s.lstrip('-'))} digits (at most {MAX_INT_DIGITS})")
        return int(s)

    try:
        return json.loads(text, object_pairs_hook=pairs, parse_int=big_int)
    except json.JSONDecodeError as e:
        raise JsonFileError(f"{src}: line {e.lineno} column {e.colno}: invalid JSON ({e.msg})") from None
    except JsonFileError as e:
        msg = str(e)
        where = ""
        m = re.match(r"duplicate key '(.*)'$", msg)
        if m:  # the line of the key's last occurrence (best effort: the hook does not know positions)
            i = text.rfind(json.dumps(m.group(1)))
            where = f" line {_line(text, i)}:" if i >= 0 else ""
        raise JsonFileError(f"{src}:{where} {msg}") from None
    except RecursionError:  # unreachable after the depth check; kept as a last line of defence
        raise JsonFileError(f"{src}: JSON nested too deeply") from None


def read_json(path: str | Path, max_bytes: int = MAX_JSON_BYTES, max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Read and parse the JSON file ``path`` within ``max_bytes`` and ``max_depth``. Raises :class:`JsonFileError`
    (too large, not UTF-8, invalid JSON, too deep, duplicate key) or ``OSError`` (cannot read)."""
    p = Path(path)
    size = p.stat().st_size
    if size > max_bytes:
        raise JsonFileError(f"{p}: {size} bytes, larger than the {max_bytes} bytes a JSON input may have")
    with open(p, "rb") as f:
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise JsonFileError(f"{p}: larger than the {max_bytes} bytes a JSON input may have")
    return parse_json(decode_text(data, str(p)), str(p), max_depth)
