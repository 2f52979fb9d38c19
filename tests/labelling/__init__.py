"""Tests: from footage to labels: frames worth labelling (sources, selection, pre-label files) and the Label
Studio round trip (push, review, pull, train) against a real server."""
