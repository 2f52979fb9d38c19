"""Ray actor implementations, installed as ``aerodaas.actors``."""
