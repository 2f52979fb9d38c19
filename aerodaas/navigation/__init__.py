"""Navigation planning that the safety gate relies on: paths around the geofence's exclusion zones
(:mod:`aerodaas.navigation.route`)."""
