"""Recording: MCAP writing, reading, recovery, JSON schemas and mission metrics."""
