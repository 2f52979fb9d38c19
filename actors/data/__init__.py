"""The data plane inside one actor (its components, the routes between actors, lock-step cascades) and the
transports it sends items on: the same-node channel (shared-memory slots and a Unix socket) and the route over Ray.
The bottom of ``aerodaas.actors``: it imports no other sub-package of it."""
