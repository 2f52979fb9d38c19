"""The built-in actors as the source an entry point hands the runtime (``aerodaas run``, ``start_mission()``):
:data:`BUILTIN` imports :mod:`aerodaas.actors.builtin.catalogue` (the actor modules, Ray, OpenCV) only when the runtime loads
it, after the application and the run's options passed their checks, so a bad application is reported without
those imports. Importing this module imports neither."""
from __future__ import annotations

from aerodaas.protocol.actor_classes import ActorClasses, ActorClassesSource

__all__ = ["BuiltinActors", "BUILTIN"]


class BuiltinActors(ActorClassesSource):
    """The built-in actor classes (:data:`aerodaas.actors.builtin.catalogue.BUILTIN_ACTORS`), imported on :meth:`load`."""

    def load(self) -> ActorClasses:
        """:data:`aerodaas.actors.builtin.catalogue.BUILTIN_ACTORS` (the first call imports the actor modules, Ray and
        OpenCV: about 0.5 s on a 2-core machine). Raises ImportError when one of them cannot be imported."""
        from aerodaas.actors.builtin.catalogue import BUILTIN_ACTORS  # lazy: the point of this class

        return BUILTIN_ACTORS


#: the source of every run started by ``aerodaas run`` or ``start_mission()``
BUILTIN = BuiltinActors()
