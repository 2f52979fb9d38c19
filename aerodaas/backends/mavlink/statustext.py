"""Status texts (MAVLink STATUSTEXT, common.xml; long texts in chunks, mavlink.io "Status text"): reassembled, kept
for the refusals that quote the autopilot's reason (:class:`~aerodaas.backends.base.CommandRefused`), reported as
``status_text`` events and log lines. A concern object of :class:`~aerodaas.backends.mavlink.MavlinkBackend`
(:class:`StatusTexts`)."""
from __future__ import annotations

import time
from collections import deque
from typing import Any, Callable

from aerodaas.backends.mavlink._common import _enum_name, _log_level, log, _STATUSTEXT_FLUSH_S, _STATUSTEXT_LEN


class StatusTexts:
    """The autopilot's status texts: the last 50 whole ones (wall time received, MAV_SEVERITY, text) and the long
    ones being reassembled. Fed by the I/O thread (:meth:`on_statustext`, :meth:`flush_stale`); read by the command
    and mission protocols (:meth:`since`) and the failsafe check (:meth:`recent`). ``robot_id`` names the log lines,
    ``event`` records a backend event. :attr:`ekf_using_gps`: ArduPilot's "EKFn IMUm is using GPS" seen."""

    def __init__(self, robot_id: str, *, event: Callable[..., None]) -> None:
        self.robot_id, self._event = robot_id, event
        self._texts: deque[tuple[float, int, str]] = deque(maxlen=50)
        #: long STATUSTEXTs being reassembled: (component, id) -> {"t": first chunk, "severity", "parts": {seq: text}}
        self._chunks: dict[tuple[int, int], dict[str, Any]] = {}
        #: ArduPilot's "EKFn IMUm is using GPS" seen (action.py readiness)
        self.ekf_using_gps = False

    def on_statustext(self, msg: Any, now: float) -> None:
        """STATUSTEXT (common.xml): ``id`` 0 is a complete text; a non-zero ``id`` marks chunks of one long text
        (MAVLink 2 extensions ``id``, ``chunk_seq`` from 0), ended by a chunk shorter than the 50-byte field
        (pymavlink cuts the text at its NUL) or, if that one is lost, by :data:`_STATUSTEXT_FLUSH_S`. Chunks are
        joined as bytes and decoded (UTF-8) once whole, so a character split across two chunks survives."""
        raw = msg.text if isinstance(msg.text, bytes) else str(msg.text).encode("utf-8", errors="replace")
        raw = raw.split(b"\x00", 1)[0]
        sid = getattr(msg, "id", 0) or 0
        if not sid:
            self._emit(now, msg.severity, raw.decode("utf-8", errors="replace"))
            return
        key = (msg.get_srcComponent(), sid)
        buf = self._chunks.get(key)
        seq = getattr(msg, "chunk_seq", 0) or 0
        if buf is not None and seq in buf["parts"]:  # the id came round again: the old text lost its last chunk
            self._flush(key)
            buf = None
        if buf is None:
            buf = self._chunks[key] = {"t": now, "severity": msg.severity, "parts": {}}
        buf["parts"][seq] = raw
        if len(raw) < _STATUSTEXT_LEN:
            self._flush(key)

    def _flush(self, key: tuple[int, int]) -> None:
        buf = self._chunks.pop(key, None)
        if buf is not None:
            whole = b"".join(buf["parts"][k] for k in sorted(buf["parts"]))
            self._emit(buf["t"], buf["severity"], whole.decode("utf-8", errors="replace"))

    def _emit(self, t: float, severity: int, text: str) -> None:
        """One whole status text: kept for :class:`CommandRefused`, a ``status_text`` event and a log line.
        ArduPilot's "EKFn IMUm is using GPS" also marks the EKF's position estimate as ready (action.py)."""
        text = text.strip()
        if "is using GPS" in text and text.startswith("EKF"):
            self.ekf_using_gps = True
        self._texts.append((t, severity, text))
        self._event("status_text", severity=_enum_name("MAV_SEVERITY", severity), text=text)
        log.log(_log_level(severity), "%s: %s", self.robot_id, text)

    def since(self, since: float, wait_s: float = 0.3) -> str:
        """The autopilot's latest STATUSTEXT sent since ``since`` (waiting up to ``wait_s`` for one, and up to
        :data:`_STATUSTEXT_FLUSH_S` longer while a chunked one begun since then is incomplete), else the latest of
        the 2 s before."""
        end = time.monotonic() + wait_s
        while True:
            texts = [t for t in list(self._texts) if t[0] >= since]
            pending = any(b["t"] >= since for b in list(self._chunks.values()))
            if (texts and not pending) or time.monotonic() >= end + (_STATUSTEXT_FLUSH_S if pending else 0.0):
                break
            time.sleep(0.01)
        if not texts:
            texts = [t for t in list(self._texts) if t[0] >= since - 2.0]
        return texts[-1][2] if texts else ""

    def flush_stale(self, now: float) -> None:
        """Emit every long text whose last chunk has not come within
:data:`_STATUSTEXT_FLUSH_S` wall seconds of its first (``now``: wall)."""
        for key, buf in list(self._chunks.items()):
            if now - buf["t"] > _STATUSTEXT_FLUSH_S:
                self._flush(key)

    def recent(self, now: float, within_s: float = 2.0) -> list[str]:
        """The texts received in the ``within_s`` wall seconds before ``now``, oldest first."""
        return [t for (ts, _sev, t) in self._texts if now - ts <= within_s]
