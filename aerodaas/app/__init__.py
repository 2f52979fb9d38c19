"""The application API (paper Table 2): environment, robots, sensors, compute (the data model is `aerodaas.model`)."""
