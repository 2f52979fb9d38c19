"""Cluster configurations and helpers, installed as ``aerodaas.clusters`` (local multi-node clusters for tests and benchmarks)."""
