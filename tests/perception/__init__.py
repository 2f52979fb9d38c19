"""Tests: detectors, tiling, tracking, geolocation, the aerial model and its training."""
