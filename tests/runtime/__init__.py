"""Tests: the runtime end to end: actors, data plane, missions, summaries, faults."""
