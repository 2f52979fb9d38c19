"""One copy of the ground texture per machine: the mip pyramid of a world's ground, shared read-only by every
process that renders it.

Every drone actor that renders a simulated camera used to build the ground texture and its mip pyramid in its
own heap: with the default ground (120 m at 0.05 m/px, a (2400, 2400, 3) uint8 texture and five smaller levels)
that is ~23 MB of private memory per drone actor, plus the float32 scratch buffers of
:func:`~aerodaas.sim.world.procedural_ground` while it is built. Here the levels are written once, as ``.npy``
files, to a per-user directory on a RAM-backed file system (``/dev/shm`` where it exists, else the temporary
directory) under a key hashed from the ground's configuration (and the image file's size and modification time),
and every process maps them with ``numpy.load(mmap_mode="r")``: the pages live once in the page cache and the
proportional set size (PSS) of each of N mapping processes counts 1/N of them.

The first writer builds into a private temporary directory and renames it into place (``rename`` is atomic on
POSIX), so a reader never sees a half-written pyramid; a concurrent builder that loses the race uses the winner's
copy. Set ``AERODAAS_GROUND_CACHE=0`` to keep the pyramid in the process heap (the former behaviour). Cached
pyramids are small (~23 MB for the default ground) and are left for the next run; delete the directory
(:func:`cache_dir`) to reclaim them.
"""
from __future__ import annotations

import hashlib
import json
import os
import pathlib
import shutil
import tempfile
from typing import Callable

import numpy as np

Level = tuple[np.ndarray, float, tuple[float, float]]


def enabled() -> bool:
    """False when ``AERODAAS_GROUND_CACHE`` is ``0``/``false``/``no``/``off``."""
    return os.environ.get("AERODAAS_GROUND_CACHE", "1").strip().lower() not in ("0", "false", "no", "off")


def cache_dir() -> pathlib.Path:
    """The per-user cache directory: ``AERODAAS_GROUND_CACHE_DIR`` when set, else
    ``/dev/shm/aerodaas-ground-<uid>`` (RAM-backed) when ``/dev/shm`` is writable, else
    ``<tempdir>/aerodaas-ground-<uid>``."""
    if os.environ.get("AERODAAS_GROUND_CACHE_DIR"):
        return pathlib.Path(os.environ["AERODAAS_GROUND_CACHE_DIR"])
    base = "/dev/shm" if os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()
    return pathlib.Path(base) / f"aerodaas-ground-{os.getuid()}"


def ground_key(ground_json: str, image: str | None) -> str:
    """Hex key of a ground: SHA-256 of its configuration (JSON) and, with an image, the image's size and
    modification time (ns), so an edited image is not served from an old copy."""
    h = hashlib.sha256(ground_json.encode())
    if image:
        st = os.stat(image)
        h.update(f"|{st.st_size}|{st.st_mtime_ns}".encode())
    return h.hexdigest()[:32]


def _load(d: pathlib.Path) -> list[Level]:
    meta = json.loads((d / "meta.json").read_text())
    return [(np.load(d / f"level{i}.npy", mmap_mode="r"), float(m["mpp"]), (float(m["home"][0]), float(m["home"][1])))
            for i, m in enumerate(meta["levels"])]


def shared_levels(key: str, build: Callable[[], list[Level]]) -> list[Level]:
    """The pyramid stored under ``key``, mapped read-only; built with ``build()`` and stored first when absent.

    Returns a list of ((H, W, 3) uint8 BGR read-only array, metres per pixel, home pixel (x, y)). Any OS error
    while storing (no space, read-only file system) falls back to the pyramid ``build()`` returned, in the heap."""
    root = cache_dir()
    final = root / key
    if (final / "meta.json").exists():
        try:
            return _load(final)
        except (OSError, ValueError, KeyError):
            pass  # a damaged copy: rebuild below
    levels = build()
    tmp = None
    try:
        root.mkdir(mode=0o700, exist_ok=True)
        tmp = pathlib.Path(tempfile.mkdtemp(prefix=f".{key}-", dir=root))
        for i, (a, _, _) in enumerate(levels):
            np.save(tmp / f"level{i}.npy", np.ascontiguousarray(a))
        meta = {"levels": [{"mpp": m, "home": [h[0], h[1]]} for _, m, h in levels]}
        (tmp / "meta.json").write_text(json.dumps(meta))
        try:
            os.rename(tmp, final)
            tmp = None
        except OSError:  # another process stored it first (or a damaged copy is in the way)
            if not (final / "meta.json").exists():
                shutil.rmtree(final, ignore_errors=True)
                os.rename(tmp, final)
                tmp = None
        return _load(final)
    except OSError:
        return levels
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
