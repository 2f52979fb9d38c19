"""The shared-memory slots of the same-node channel (:mod:`aerodaas.actors.data.channel`): the segments a sender
creates for its frames (:class:`Slot`, named by :func:`own_prefix`) and the receiver's mapping of one of them
(:func:`attach`), which never makes the receiver the segment's owner."""
from __future__ import annotations

import os
import secrets
import sys
from multiprocessing import resource_tracker
from multiprocessing.shared_memory import SharedMemory
from typing import Any

__all__ = ["Slot", "attach", "create_segment", "own_prefix", "release_lent"]


def own_prefix() -> str:
    """The name prefix of the shared-memory segments this process creates (:func:`create_segment`): its pid, so a
    segment of this very process is known by its name alone (no table of them kept)."""
    return f"adc{os.getpid()}_"


def create_segment(size: int) -> SharedMemory:
    """A new segment of ``size`` bytes named :func:`own_prefix` + 12 random hex digits (23 characters at most: the
    31 of macOS's ``PSHMNAMLEN``); a name in use is drawn again, as ``SharedMemory`` does with its own names."""
    while True:
        try:
            return SharedMemory(name=own_prefix() + secrets.token_hex(6), create=True, size=size)
        except FileExistsError:
            continue


def attach(name: str) -> SharedMemory:
    """Map the sender's segment ``name`` without making this process's resource tracker its owner (before Python
    3.13 an attached segment is registered too, and would be unlinked when this process exits)."""
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
