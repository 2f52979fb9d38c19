"""Tests: from footage to labels: the Label Studio round trip (push, review, pull, train) against a real server."""
