"""What a run's driver computes when it exports an actor class to Ray.

Ray exports each actor class once per job, on its first ``.remote()`` (``FunctionActorManager.export_actor_class``,
``ray/_private/function_manager.py``, Ray 2.60): the pickled class, its method names, and a
``collision_identifier``, the SHA-256 of the text ``dis.dis(cls, depth=2)`` prints for the class, meant for a
warning about a class exported again and again. Nothing in Ray reads that identifier back (the stored record is a
Python pickle the GCS does not open, and no Python code of Ray 2.60 reads the field); yet disassembling the run's
actor classes, every method two levels deep, is CPU the driver spends between attaching to Ray and asking for
its actors, on the way to the first frame.

:func:`light_collision_identifier` makes this process compute it from the class's module, qualified name and
name instead: the same class still gives the same identifier, and an export is otherwise unchanged (the same
pickled class, key and method names reach the workers).
"""
from __future__ import annotations

import hashlib
from typing import Any

__all__ = ["light_collision_identifier", "name_identifier"]


def name_identifier(_manager: Any, function_or_class: Any) -> bytes:
    """``compute_collision_identifier``'s replacement: SHA-256 (32 bytes) of ``module:qualname:name`` of
    ``function_or_class``."""
    key = ":".join(str(getattr(function_or_class, attr, "")) for attr in ("__module__", "__qualname__", "__name__"))
    return hashlib.sha256(key.encode("utf-8")).digest()


def light_collision_identifier() -> bool:
    """In this process, Ray's exports identify a class by :func:`name_identifier` (see the module). Returns True
    when in effect, False when this Ray has no ``FunctionActorManager.compute_collision_identifier`` (nothing is
    changed then)."""
    try:
        from ray._private.function_manager import FunctionActorManager  # lazy: heavy ray
    except ImportError:
        return False
    if not callable(getattr(FunctionActorManager, "compute_collision_identifier", None)):
        return False
    FunctionActorManager.compute_collision_identifier = name_identifier
    return True
