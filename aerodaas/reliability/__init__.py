"""The bad-input and fault catalogue (``python -m aerodaas.reliability``)."""
