"""Tests: the MAVLink and Tello backends against the emulators, mission files and upload, signing, links."""
