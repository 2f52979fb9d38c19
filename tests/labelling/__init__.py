"""Tests: frames worth labelling (``aerodaas label frames``): sources, selection, pre-label files."""
