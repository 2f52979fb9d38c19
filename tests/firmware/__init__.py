"""Tests: real ArduCopter and PX4 SITL firmware in private network namespaces (the sitl marker)."""
