"""``aerodaas schema``: the JSON Schema of environment.json."""
from __future__ import annotations

import argparse
import json

def run(args: argparse.Namespace) -> int:
    """``aerodaas schema``: print the JSON Schema of ``environment.json`` (:func:`aerodaas.config.json_schema`)."""
    from aerodaas.config import json_schema  # lazy: CLI start-up (pydantic)

    print(json.dumps(json_schema(), indent=2))
    return 0


def add_parser(sub) -> None:
    """``aerodaas schema``."""
    sub.add_parser("schema", help="print the JSON Schema of environment.json").set_defaults(func=run)
