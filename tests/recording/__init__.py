"""Tests: MCAP recording, accounting, segments, replay and plots."""
