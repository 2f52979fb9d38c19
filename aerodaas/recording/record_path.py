"""Where a recording may be written, checked before a run starts, and how a file is known as one of ours.

:func:`check_record_path` is what ``aerodaas run --record PATH`` runs before anything starts (outputs never clobber
inputs); :func:`is_aerodaas_recording` reads an MCAP file's header record for the :data:`LIBRARY` the writer
(:class:`aerodaas.recording.writer.McapRecorder`) names in it.
"""
from __future__ import annotations

import os
from pathlib import Path
import stat
from typing import NamedTuple

#: the library name the writer puts in every recording's MCAP Header record
LIBRARY = "aerodaas"
#: the MCAP magic (MCAP specification, "Magic") that every recording starts with
MCAP_MAGIC = b"\x89MCAP0\r\n"


class RunInput(NamedTuple):
    """A file the run reads, which a recording never overwrites: ``path`` and ``what`` names it in the refusal (the
    environment field that named it, e.g. ``world.ground.image``)."""

    path: str
    what: str


def is_aerodaas_recording(p: Path) -> bool:
    """Whether the file at ``p`` starts as a recording of ours: the MCAP magic, then a Header record (opcode 0x01)
    whose library is :data:`LIBRARY` (MCAP specification: Header = profile string, library string)."""
    try:
        with open(p, "rb") as f:
            head = f.read(512)
    except OSError:
        return False
    if not head.startswith(MCAP_MAGIC) or len(head) < 9 + 8 + 4 or head[8] != 0x01:
        return False
    body = head[17:]
    n = int.from_bytes(body[:4], "little")
    lib_at = 4 + n
    m = int.from_bytes(body[lib_at:lib_at + 4], "little")
    return body[lib_at + 4:lib_at + 4 + m].decode("utf-8", "replace").startswith(LIBRARY)


def check_record_path(path: str | os.PathLike, *, overwrite: bool = False,
                      protect: tuple[str | os.PathLike | RunInput, ...] = ()) -> Path:
    """Check, before anything starts, that a recording can be written at ``path``; returns the absolute path.

    The folder must already exist (nothing is created: a typo must not leave directories behind), the path must be
    a regular file or not exist yet (``/dev/full``, ``/dev/null``, FIFOs and directories are refused), and the file
    must be creatable there (``/proc/x.mcap`` is not). Outputs never clobber inputs: an existing file that is not an
    AeroDaaS recording (:func:`is_aerodaas_recording`) is refused unless ``overwrite`` (``--overwrite``), and the
    files in ``protect`` (the application, its environment file, every file the environment names: a
    :class:`RunInput` is named by its field) always, a recording of ours too (a replayed log or a recorded camera's
    MCAP is one). An existing file is left as it is until the run starts. Raises ValueError naming the path and the
    reason."""
    p = Path(os.path.abspath(os.path.expanduser(str(path))))
    if not p.parent.is_dir():
        raise ValueError(f"--record {str(path)!r}: folder {str(p.parent)!r} does not exist (create it first)")
    if p.exists() or p.is_symlink():
        try:
            mode = p.stat().st_mode
        except OSError as e:
            raise ValueError(f"--record {str(path)!r}: {e.strerror}") from None
        if not stat.S_ISREG(mode):
            raise ValueError(f"--record {str(path)!r}: not a regular file (a device, directory or pipe cannot hold "
                             f"a recording)")
        if not os.access(p, os.W_OK):
            raise ValueError(f"--record {str(path)!r}: the file is not writable")
        for q in protect:
            where = q.path if isinstance(q, RunInput) else q
            try:
                same = where is not None and os.path.samefile(p, where)
            except OSError:
                same = False
            if same:
                named = f"{q.what}: {q.path!r}" if isinstance(q, RunInput) else repr(str(q))
                raise ValueError(f"--record {str(path)!r} is an input of this run ({named}): a recording never "
                                 f"overwrites the application, its environment file or a file the environment "
                                 f"names")
        if not overwrite and not is_aerodaas_recording(p):
            raise ValueError(f"--record {str(path)!r}: the file exists and is not an AeroDaaS recording; pass "
                             f"--overwrite to replace it")
        return p
    try:
        fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    except OSError as e:
        raise ValueError(f"--record {str(path)!r}: cannot create the file: {e.strerror}") from None
    os.close(fd)
    os.unlink(p)
    return p
