"""What the driver and the actors exchange, below both: the typed messages (``messages.py``), the actor specs
(``specs.py``), component ids (``ids.py``) and the start-up probe (``startup_probe.py``)."""
