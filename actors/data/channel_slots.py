"""The shared-memory slots of the same-node channel (:mod:`aerodaas.actors.data.channel`): the segments a sender
creates for its frames (:class:`Slot`, named by :func:`own_prefix`) and the receiver's mapping of one of them
(:func:`attach`), which never makes the receiver the segment's owner.

A segment is a POSIX shared-memory object (``/dev/shm/<name>`` on Linux, what ``shm_open(3)`` makes) mapped with
:mod:`mmap` (:class:`Segment`): unlike :class:`multiprocessing.shared_memory.SharedMemory` before Python 3.13, it
starts no resource-tracker process in each actor that creates or maps one. Each process that maps a segment holds a
shared ``flock(2)`` on it while it does. The sender unlinks its segments when its outlet closes; those that nobody
maps any more (their sender died first) are unlinked by :func:`aerodaas.clusters.reaper.sweep_segments` (each new
segment sweeps them, and so does a local run's reaper). Where there is no ``/dev/shm``, ``SharedMemory`` (and its
tracker) is used instead.
"""
from __future__ import annotations

import fcntl
import mmap
import os
import secrets
import sys
from multiprocessing import resource_tracker
from multiprocessing.shared_memory import SharedMemory
from typing import Any

from aerodaas.clusters.reaper import SEGMENT_NAME, SHM_DIR, segment_prefix, sweep_segments

__all__ = ["Mapped", "Segment", "Slot", "attach", "create_segment", "own_prefix", "release_lent"]


def own_prefix() -> str:
    """The name prefix of the shared-memory segments this process creates (:func:`create_segment`): its pid
    (:func:`aerodaas.clusters.reaper.segment_prefix`), so a segment of this very process is known by its name
    alone (no table of them kept)."""
    return segment_prefix(os.getpid())


class Segment:
    """A same-node channel's shared-memory segment ``name`` (:data:`aerodaas.clusters.reaper.SEGMENT_NAME`) of
    ``size`` bytes in ``shm_dir``, mapped here: ``buf`` is a writable :class:`memoryview` over the mapping, and this
    process holds a shared ``flock(2)`` on the segment while it maps it (a sweep leaves it alone). ``create``: a new
    segment, readable and writable by this user only. The interface of
    :class:`multiprocessing.shared_memory.SharedMemory` (``name``, ``size``, ``buf``, :meth:`close`, :meth:`unlink`),
    without its resource tracker.

    Raises ValueError for a name that is not a channel segment's or a new segment's size under 1 byte,
    FileExistsError when a new segment's name is taken, FileNotFoundError when an existing one is gone (or a new one
    was swept before it was locked: draw another name), and ValueError for an existing segment of 0 bytes."""

    def __init__(self, name: str, create: bool = False, size: int = 0, shm_dir: str = SHM_DIR) -> None:
        self.buf: memoryview | None = None
        self._mmap: mmap.mmap | None = None
        if SEGMENT_NAME.fullmatch(name) is None:
            raise ValueError(f"not a channel segment's name: {name!r}")
        if create and size <= 0:
            raise ValueError(f"a new shared-memory segment needs a positive size, not {size}")
        self._path = os.path.join(shm_dir, name)
        fd = os.open(self._path, os.O_RDWR | os.O_NOFOLLOW | (os.O_CREAT | os.O_EXCL if create else 0), 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_SH)  # held by the mapping (mmap keeps a duplicate of fd) until it is closed
            if create:
                if os.stat(self._path).st_ino != os.fstat(fd).st_ino:  # swept between the open and the lock
                    raise FileNotFoundError(f"shared-memory segment {name} was swept before it was locked")
                os.ftruncate(fd, size)
            else:
                size = os.fstat(fd).st_size
            self._mmap = mmap.mmap(fd, size)
        except BaseException:
            if create:
                try:
                    if os.stat(self._path).st_ino == os.fstat(fd).st_ino:
                        os.unlink(self._path)
                except OSError:
                    pass
            raise
        finally:
            os.close(fd)
        self.name, self.size = name, size
        self.buf = memoryview(self._mmap)

    def close(self) -> None:
        """Unmap the segment here and release its lock. numpy holds no buffer export on ``buf``: an array made over
        it must not be used after this (callers keep the segment until their last such array is collected)."""
        if self.buf is not None:
            self.buf.release()
            self.buf = None
        if self._mmap is not None:
            self._mmap.close()
            self._mmap = None

    def unlink(self) -> None:
        """Remove the segment's name (FileNotFoundError when it is gone); whoever maps it keeps the mapping."""
        os.unlink(self._path)

    def __del__(self) -> None:
        try:
            self.close()
        except (BufferError, OSError):
            pass


#: a slot segment as mapped: a :class:`Segment` where there is ``/dev/shm``, CPython's ``SharedMemory`` elsewhere (the
#: same members either way)
Mapped = Segment | SharedMemory


def _has_dev_shm() -> bool:
    return os.path.isdir(SHM_DIR)


def create_segment(size: int) -> Mapped:
    """A new segment of ``size`` bytes named :func:`own_prefix` + 12 random hex digits (23 characters at most: the
    31 of macOS's ``PSHMNAMLEN``); a name in use is drawn again, as ``SharedMemory`` does with its own names. The
    segments that nobody maps any more are unlinked first. Raises OSError when the segment cannot be made (``/dev/shm``
    full)."""
    tracker_free = _has_dev_shm()
    if tracker_free:
        sweep_segments()
    while True:
        name = own_prefix() + secrets.token_hex(6)
        try:
            return Segment(name, create=True, size=size) if tracker_free else \
                SharedMemory(name=name, create=True, size=size)
        except (FileExistsError, FileNotFoundError):  # taken, or swept before it was locked: draw another
            continue


def attach(name: str) -> Mapped:
    """Map the sender's segment ``name`` without making this process its owner (``SharedMemory`` before Python
    3.13, where there is no ``/dev/shm``, registers an attached segment too, which would be unlinked when this process
    exits: undone here). Raises what :class:`Segment` raises (FileNotFoundError when the segment is gone)."""
    if _has_dev_shm():
        return Segment(name)
    if sys.version_info >= (3, 13):
        return SharedMemory(name=name, create=False, track=False)
    shm = SharedMemory(name=name, create=False)
    if not name.startswith(own_prefix()):  # a segment of this very process (tests) stays registered: ours to unlink
        try:
            resource_tracker.unregister(shm._name, "shared_memory")  # noqa: SLF001 - the documented workaround
        except Exception:  # noqa: BLE001 - not registered: nothing to undo
            pass
    return shm


class Slot:
    """One segment of a sender's frames: ``size`` bytes; ``free`` while no receiver holds the frame written in it;
    ``lent`` while a frame made in it in this process (:meth:`~aerodaas.actors.data.channel_outlet.ChannelOutlet.lend`) is still referenced
    here. It may be written again only when free and not lent."""

    __slots__ = ("shm", "size", "free", "lent", "dropped")

    def __init__(self, size: int) -> None:
        self.shm = create_segment(size)
        self.size, self.free, self.lent, self.dropped = size, True, False, False

    def drop(self) -> None:
        """Unlink the segment (a receiver still mapping it keeps its mapping until it lets go) and unmap it here —
        unless a lent frame here still uses it: then it is unmapped when that frame is collected
        (:func:`release_lent`), never under a live array (numpy holds no buffer export that would stop it)."""
        self.dropped = True
        try:
            self.shm.unlink()
        except OSError:
            pass
        if not self.lent:
            try:
                self.shm.close()
            except (OSError, BufferError):
                pass


def release_lent(unlent: Any, slot: Slot) -> None:
    """Finalizer of a lent frame (:meth:`~aerodaas.actors.data.channel_outlet.ChannelOutlet.lend`): its slot's name joins ``unlent``
    (the outlet makes it writable again under its lock); a slot dropped meanwhile (the outlet closed) is unmapped
    now that nothing here uses it. Holding ``slot`` keeps the mapping alive as long as the frame is."""
    if slot.dropped:
        slot.lent = False
        try:
            slot.shm.close()
        except (OSError, BufferError):
            pass
    else:
        unlent.append(slot.shm.name)
