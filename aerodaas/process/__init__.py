"""The state a Python process has once, whatever runs in it (``state.py``: :data:`~aerodaas.process.state.PROCESS`):
the driver's stop signals and Ray connection, and the MAVLink connections that the robots of one process share.
At the bottom of the layers, so that the runtime and the vehicle backends both reach it."""
