"""The identifier a run's driver gives an actor class it exports to Ray (aerodaas.clusters.ray_exports): from the
class's names, without disassembling it."""
from __future__ import annotations

import dis

from aerodaas.clusters import ray_exports


class _Recorder:
    def write(self, x):
        return x


class _Drone:
    def fly(self, x):
        return x


def test_the_identifier_names_the_class_without_disassembling_it(monkeypatch):
    from ray._private.function_manager import FunctionActorManager

    before = FunctionActorManager.compute_collision_identifier
    try:
        assert ray_exports.light_collision_identifier()
        monkeypatch.setattr(dis, "dis", lambda *a, **k: (_ for _ in ()).throw(AssertionError("disassembled")))
        ident = FunctionActorManager.compute_collision_identifier
        first = ident(None, _Recorder)
        assert isinstance(first, bytes) and len(first) == 32
        assert ident(None, _Recorder) == first  # the same class, the same identifier
        assert ident(None, _Drone) != first
    finally:
        FunctionActorManager.compute_collision_identifier = before
