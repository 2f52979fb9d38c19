"""The exact-timing policy harness now lives in production code (:mod:`aerodaas.bench.harness`, used by
``aerodaas bench schedulers --harness``); this module re-exports it for the policy tests."""
from aerodaas.bench.harness import Harness, Result, fleet_tasks, make_trace, run_fleet, run_policy  # noqa: F401
