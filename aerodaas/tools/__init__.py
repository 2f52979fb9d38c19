"""Tools around runs: figures from recordings and the human-in-the-loop API."""
