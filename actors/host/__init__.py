"""The actor process that hosts components: :class:`~aerodaas.actors.host.base.ActorBase` (what every actor of a
run shares), the assembly that builds an actor's components from its spec and runs its clock, Ray plumbing, and
the Ray actor classes built on it (the drone, analytics and dispatcher actors)."""
