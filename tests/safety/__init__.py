"""Tests: geofences, limits, holds, phase deadlines, failsafes, TLS and secrets."""
