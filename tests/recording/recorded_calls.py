"""A stand-in for the recorder a drone writes to, for tests that run the drone's flight logic without Ray
(tests/firmware/sitl_no_lift.py, tests/plugins/test_example_rover.py): events and mission states kept in memory, in order."""
from __future__ import annotations


class RecordedCalls:
    """The recorder's calls a drone makes: ``events`` (each event dict) and ``states`` (mission state names)."""

    def __init__(self) -> None:
        self.events: list[dict] = []
        self.states: list[str] = []

    def json(self, topic: str, t_ns: int, msg: dict, schema: str) -> None:
        if topic.endswith("/events"):
            self.events.append(msg)
        elif topic == "/mission/state":
            self.states.append(msg["state"])

    def odometry(self, *args, **kwargs) -> None:
        pass
