"""Tests: analytics and trajectory schedulers, DEMS/LAPLAN policies and their harness."""
