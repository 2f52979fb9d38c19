"""The application API (paper Table 2): environment, robots, sensors, compute, data containers, the data model."""
