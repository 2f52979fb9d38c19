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
copy. Set ``AERODAAS_GROUND_CACHE=0`` to keep the pyramid in the process heap (the former behaviour).

Cached pyramids (~23 MB for the default ground) are left for the next run, which maps instead of building them
(0.6-1.1 s of CPU per actor saved). The cache is bounded: storing a pyramid first removes the least recently
used others beyond ``AERODAAS_GROUND_CACHE_MB`` (default 512 MB) and any builder's temporary directory older
than an hour (a crashed builder's); ``aerodaas down`` removes it all (:func:`clear`). Removing a pyramid that a
running process maps is safe: the process keeps its pages until it unmaps them, and a process that finds a
pyramid gone while loading it builds its own.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import fcntl
import hashlib
import json
import os
import pathlib
import shutil
import tempfile
import time
from typing import Callable

import numpy as np

Level = tuple[np.ndarray, float, tuple[float, float]]

#: default bound of the cache (MB); ``AERODAAS_GROUND_CACHE_MB`` overrides it
DEFAULT_LIMIT_MB = 512
#: a builder's temporary directory older than this (s) belongs to a builder that died
STALE_BUILD_S = 3600.0


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


def limit_bytes() -> int:
    """The cache's bound in bytes: ``AERODAAS_GROUND_CACHE_MB`` (a number >= 0) or :data:`DEFAULT_LIMIT_MB`.
    Raises ValueError naming the variable and its value when it is not a number >= 0."""
    raw = os.environ.get("AERODAAS_GROUND_CACHE_MB", "").strip()
    if not raw:
        return DEFAULT_LIMIT_MB * 1_000_000
    try:
        mb = float(raw)
    except ValueError:
        mb = -1.0
    if not mb >= 0:
        raise ValueError(f"AERODAAS_GROUND_CACHE_MB must be a number of megabytes >= 0, got {raw!r}")
    return int(mb * 1_000_000)


def _size(d: pathlib.Path) -> int:
    total = 0
    for f in d.iterdir() if d.is_dir() else ():
        try:
            total += f.stat().st_size
        except OSError:
            pass
    return total


def _entries(root: pathlib.Path) -> list[tuple[float, pathlib.Path, int]]:
    """``(last use, directory, bytes)`` of every stored pyramid; last use is the modification time of its
    ``meta.json`` (s since the epoch), which :func:`shared_levels` touches on every load."""
    out = []
    for d in root.iterdir() if root.is_dir() else ():
        if d.name.startswith(".") or not d.is_dir():
            continue
        try:
            st = (d / "meta.json").stat()
        except OSError:
            continue
        out.append((st.st_mtime, d, _size(d)))
    return out


def prune(keep: str | None = None, limit: int | None = None, incoming: int = 0) -> int:
    """Remove the least recently used pyramids until the rest and ``incoming`` bytes (a pyramid about to be
    stored) fit ``limit`` bytes (default :func:`limit_bytes`), never the one under ``keep``, and builders'
    temporary directories older than :data:`STALE_BUILD_S`. Returns the bytes removed; OS errors leave an entry in
    place."""
    root = cache_dir()
    limit = (limit_bytes() if limit is None else int(limit)) - int(incoming)
    removed = 0
    now = time.time()
    for d in root.iterdir() if root.is_dir() else ():
        try:
            if d.name.startswith(".") and now - d.stat().st_mtime > STALE_BUILD_S:
                size = _size(d)  # 0 for a builder's lock file
                if d.is_dir():
                    shutil.rmtree(d)
                else:
                    d.unlink()
                removed += size
        except OSError:
            pass
    entries = sorted(_entries(root), key=lambda e: e[0])
    total = sum(e[2] for e in entries)
    for _, d, size in entries:
        if total <= limit:
            break
        if d.name == keep:
            continue
        try:
            shutil.rmtree(d)
        except OSError:
            continue
        total -= size
        removed += size
    return removed


def clear() -> int:
    """Remove the whole cache directory (:func:`cache_dir`); returns the bytes it held (0 when absent)."""
    root = cache_dir()
    if not root.is_dir():
        return 0
    size = sum(_size(d) for d in root.iterdir() if d.is_dir())
    shutil.rmtree(root, ignore_errors=True)
    return size


def _load(d: pathlib.Path) -> list[Level]:
    meta = json.loads((d / "meta.json").read_text())
    return [(np.load(d / f"level{i}.npy", mmap_mode="r"), float(m["mpp"]), (float(m["home"][0]), float(m["home"][1])))
            for i, m in enumerate(meta["levels"])]


def _stored(final: pathlib.Path) -> list[Level] | None:
    """The pyramid stored at ``final``, mapped (its last use recorded), or None when absent or damaged."""
    if not (final / "meta.json").exists():
        return None
    try:
        levels = _load(final)
    except (OSError, ValueError, KeyError):
        return None  # a damaged copy (or one removed meanwhile): rebuilt by the caller
    try:
        os.utime(final / "meta.json")  # its last use, for :func:`prune`
    except OSError:
        pass
    return levels


def shared_levels(key: str, build: Callable[[], list[Level]]) -> list[Level]:
    """The pyramid stored under ``key``, mapped read-only; built with ``build()`` and stored first when absent.
    One process builds it at a time (an exclusive ``flock`` on ``.<key>.lock``): the drone actors of a run, which
    start together, wait for the first one's copy instead of each building its own (0.6-1.1 s of CPU and ~60 MB
    of transient memory each).

    Returns a list of ((H, W, 3) uint8 BGR read-only array, metres per pixel, home pixel (x, y)). Any OS error
    while storing (no space, read-only file system) falls back to the pyramid ``build()`` returned, in the heap."""
    root = cache_dir()
    final = root / key
    levels = _stored(final)
    if levels is not None:
        return levels
    lock = None
    try:
        root.mkdir(mode=0o700, exist_ok=True)
        lock = open(root / f".{key}.lock", "a")  # noqa: SIM115 - held until the copy is stored
        fcntl.flock(lock, fcntl.LOCK_EX)  # released by the kernel if the holder dies
    except OSError:
        pass  # no lock (read-only, no space): build anyway, as before
    try:
        levels = _stored(final)  # stored by the process that held the lock before us
        return levels if levels is not None else _build_and_store(final, build)
    finally:
        if lock is not None:
            lock.close()


def _build_and_store(final: pathlib.Path, build: Callable[[], list[Level]]) -> list[Level]:
    """``build()``, stored at ``final`` (through a temporary directory beside it and a rename) and mapped; the
    built pyramid itself when it cannot be stored."""
    root, key = final.parent, final.name
    levels = build()
    tmp = None
    try:
        tmp = pathlib.Path(tempfile.mkdtemp(prefix=f".{key}-", dir=root))
        for i, (a, _, _) in enumerate(levels):
            np.save(tmp / f"level{i}.npy", np.ascontiguousarray(a))
        meta = {"levels": [{"mpp": m, "home": [h[0], h[1]]} for _, m, h in levels]}
        (tmp / "meta.json").write_text(json.dumps(meta))
        try:
            prune(keep=key, incoming=sum(f.stat().st_size for f in tmp.iterdir()))
        except ValueError:  # a bad AERODAAS_GROUND_CACHE_MB (refused before Ray by ``aerodaas run``): no pruning
            pass
        try:
            os.rename(tmp, final)
            tmp = None
        except OSError:  # another process stored it first (or a damaged copy is in the way)
            if not (final / "meta.json").exists():
                shutil.rmtree(final, ignore_errors=True)
                os.rename(tmp, final)
                tmp = None
        mapped = _load(final)
    except OSError:
        return levels
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    del levels
    release_heap()
    return mapped


def release_heap() -> bool:
    """Give the C heap's free memory back to the system (glibc ``malloc_trim(0)``): glibc keeps part of the freed
    float32 scratch of a pyramid's build in the process (measured outside Ray with the default ground: 77.1 MB PSS
    after building without it, 71.5 MB with it, 65.2 MB for a process that only mapped the copy). Returns False
    where there is no glibc."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return bool(libc.malloc_trim(0))
    except (OSError, AttributeError):
        return False
