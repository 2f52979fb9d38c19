"""Tests: local and multi-node Ray clusters, `ray up`, TLS between nodes, warm pools."""
