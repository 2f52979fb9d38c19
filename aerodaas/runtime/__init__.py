"""The runtime and data plane's driver side: the typed dataflow graph, messages, pre-flight checks, start-up and supervision of a run."""
