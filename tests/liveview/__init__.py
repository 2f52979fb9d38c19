"""Tests: the live view over the Foxglove WebSocket protocol and third-party clients."""
