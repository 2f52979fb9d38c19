"""The analytics scheduler inside a dispatcher actor: the analytics whose frames it places on the edge or the cloud
and the service that runs its dispatcher (:mod:`aerodaas.schedulers.dispatch`) for them."""
