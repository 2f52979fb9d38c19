"""The output stream of an MCAP recording that hands each completed chunk to the operating system.

:class:`ChunkFlushingStream` sits between :class:`mcap.writer.Writer` and the recording's file (see
:class:`aerodaas.recording.writer.McapRecorder`, its crash-safety paragraph): it knows when a record boundary was
just written, what offset the OS last took (where an unfinished file can be cut), and how to make writes fail past
a size (fault injection for the disk-failure path).
"""
from __future__ import annotations

import io
import os


class ChunkFlushingStream:
    """Minimal write-only stream handed to :class:`mcap.writer.Writer`.

    mcap's writer keeps the chunk in progress in memory and writes to its output stream only when a record leaves
    the writer: the header, a metadata record, a completed chunk (plus its message indexes), or the summary and
    footer at the end. So "something was written since the last check" means "a chunk boundary (or another
    complete record) was just reached"; :class:`McapRecorder` then calls :meth:`sync` to hand the bytes to the OS.
    ``tell()`` is answered from a counter so it costs no system call.
    """

    def __init__(self, f: io.BufferedWriter) -> None:
        self._f = f
        self._pos = f.tell()
        self.pending = False
        self.durable = self._pos  # bytes handed to the OS by the last successful flush (a record boundary)

    def write(self, data: bytes) -> int:
        n = self._f.write(data)
        self._pos += len(data)
        if data:
            self.pending = True
        return n

    def tell(self) -> int:
        return self._pos

    def seekable(self) -> bool:
        return False

    def flush(self) -> None:
        self._f.flush()
        self.pending = False
        self.durable = self._pos

    def sync(self) -> None:
        """Flush to the OS if anything was written since the last flush."""
        if self.pending:
            self.flush()

    def fail_writes_past(self, limit: int, code: int) -> None:
        """Fault injection: a write that would take the file past ``limit`` bytes raises ``OSError(code)``."""
        f, real_write = self._f, self._f.write

        def write(data: bytes) -> int:
            if f.tell() + len(data) > limit:
                raise OSError(code, os.strerror(code))
            return real_write(data)

        self._f = type("_Faulty", (), {"write": staticmethod(write), "flush": f.flush, "tell": f.tell,
                                       "fileno": f.fileno, "close": f.close})()
