"""Tests: the `aerodaas bench` commands and their harnesses."""
