"""``python -m aerodaas.reliability``: the bad-input and fault catalogue."""
from aerodaas.reliability.catalogue import main

raise SystemExit(main())
