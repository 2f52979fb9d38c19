"""The runtime, the driver side of a run: the typed dataflow graph, pre-flight checks, start-up and supervision."""
