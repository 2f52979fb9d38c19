"""IAeroData: the paper's generic data containers (``getData``/``setData``)."""
from __future__ import annotations

from typing import Any, Callable, Generic, TypeVar

E = TypeVar("E")


class AeroData(Generic[E]):
    """IAeroData<E>: a single data item with ``get_data`` / ``set_data``."""

    def __init__(self, data: E | None = None) -> None:
        self._data = data

    def get_data(self) -> E | None:
        return self._data

    def set_data(self, data: E) -> None:
        self._data = data

    @property
    def data(self) -> E | None:
        return self._data


IAeroData = AeroData


class AeroListData(AeroData[list]):
    """A list of items (e.g. the waypoints of an AeroNav)."""

    def __init__(self, data: list | None = None) -> None:
        super().__init__(list(data or []))

    def __iter__(self):
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)


class AeroStreamData(AeroData[Any]):
    """A stream (sensor output or analytics output). At build time it is a node of the dataflow graph; at run
    time :meth:`get_data` returns the newest item the stream has carried (pull access) and ``buffer`` is the
    number of items a slow consumer may have outstanding before newer ones are dropped and counted."""

    def __init__(self, source: Any, buffer: int = 1) -> None:
        super().__init__(None)
        self.source = source
        self.buffer = buffer
        self.subscribers: list[Any] = []
        self._runtime_getter = None

    def bind_runtime(self, getter: Callable[[], Any] | None) -> None:
        """While a mission runs, :meth:`get_data` returns ``getter()`` (the driver binds a pull of the stream's
        newest item from its actor); ``None`` after the run: the last value set again."""
        self._runtime_getter = getter

    def get_data(self) -> Any:
        """Newest item on the stream (needs a running mission; else the last value set, or None)."""
        if self._runtime_getter is not None:
            return self._runtime_getter()
        return self._data

    def __repr__(self) -> str:
        return f"AeroStreamData(source={getattr(self.source, 'name', self.source)!r})"
