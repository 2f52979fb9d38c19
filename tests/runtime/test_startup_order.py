"""Actors created concurrently: the driver asks Ray for every actor of a run and for every actor's
set-up before it waits for any answer, so the actors' processes start and set up side by side, not one after the
other. Checked on the order of the driver's calls, with actor classes that record them and ``ray.get`` replaced by
a recorder of its own: no Ray process, no timing, nothing that can race. (Ray's state API cannot show this
without a race: an actor may be ready before the driver asks for the next one.)"""
from __future__ import annotations

from types import SimpleNamespace

import ray

from aerodaas.runtime import driver, supervise


class _Calls:
    """The driver's calls in order: ``("create", host)``, ``("setup", host)``, ``("get", host)``."""

    def __init__(self) -> None:
        self.log: list[tuple[str, str]] = []


class _Method:
    def __init__(self, calls: _Calls, host: str, name: str) -> None:
        self.calls, self.host, self.name = calls, host, name

    def remote(self, *args, **kwargs) -> tuple[str, str]:
        if self.name == "setup":
            self.calls.log.append(("setup", self.host))
        return (self.name, self.host)


class _Handle:
    def __init__(self, calls: _Calls, host: str) -> None:
        self.setup = _Method(calls, host, "setup")
        self.keep_specs = _Method(calls, host, "keep_specs")


class _ActorClass:
    """What ``ray.remote`` makes of a class: ``options(...).remote(...)`` creates an actor (recorded)."""

    def __init__(self, calls: _Calls) -> None:
        self.calls = calls

    def options(self, **options) -> "_ActorClass":
        self.name = options.get("name", "")
        return self

    def remote(self, *args) -> _Handle:
        host = args[0] if args and isinstance(args[0], str) else "recorder"
        self.calls.log.append(("create", host))
        return _Handle(self.calls, host)


def _plan(hosts: list[str]) -> SimpleNamespace:
    actor = SimpleNamespace(name="rec", spec=None, role="recorder", tier="edge")
    others = {h: SimpleNamespace(name=h, spec=None, role="drone" if h.startswith("drone") else "analytics",
                                 tier="edge", ray_options=lambda placement, restarts: {})
              for h in hosts}
    return SimpleNamespace(actors={"recorder": actor, **others})


def test_every_actor_and_its_setup_is_asked_for_before_the_first_wait(monkeypatch):
    calls = _Calls()
    cls = _ActorClass(calls)
    classes = SimpleNamespace(recorder=cls, for_role=lambda role: cls)
    hosts = ["drone/a", "drone/b", "analytics/edge/detector#1", "analytics/edge/detector#2"]
    env = SimpleNamespace(cfg=SimpleNamespace(actor_max_restarts=0))
    run = SimpleNamespace(scheduled={}, plan=_plan(hosts), env=env, classes=classes, robot_errors={},
                          robot_refused=set())

    def fake_get(ref, *a, **kw):
        calls.log.append(("get", ref[1]))
        return {"host": ref[1]}

    monkeypatch.setattr(ray, "get", fake_get)
    monkeypatch.setattr(ray, "get_runtime_context", lambda: SimpleNamespace(get_node_id=lambda: "0" * 56))
    monkeypatch.setattr(supervise, "recorder_specs", lambda plan: ({}, b""))  # where start_actors looks it up
    described = driver._start_actors(run, placement=None)

    first_get = next(i for i, (kind, _) in enumerate(calls.log) if kind == "get")
    before = calls.log[:first_get]
    assert {h for kind, h in before if kind == "create"} == {"recorder", *hosts}, calls.log
    assert {h for kind, h in before if kind == "setup"} == {"recorder", *hosts}, calls.log
    assert sorted(d["host"] for d in described) == sorted(hosts)
    # the recorder's answer is kept (its live view's URL): asked once, read once
    assert run.recorder_described == {"host": "recorder"}
    assert [c for c in calls.log if c == ("setup", "recorder")] == [("setup", "recorder")]
    assert [c for c in calls.log if c == ("get", "recorder")] == [("get", "recorder")]
