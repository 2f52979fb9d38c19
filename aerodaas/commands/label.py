"""``aerodaas label``: from footage to labels. ``push`` and ``pull`` carry frames and pre-labels to a Label Studio
project and the reviewed boxes back as training sets; ``serve`` is the detector as its ML backend
(:mod:`aerodaas.commands.label_studio`)."""
from __future__ import annotations

from aerodaas.commands.label_studio import add_label_studio_parsers


def add_parser(sub) -> None:
    """Register ``label`` and its sub-commands on the CLI's sub-parsers ``sub``."""
    lp = sub.add_parser("label", help="label your own footage: Label Studio push, pull and serve")
    lsub = lp.add_subparsers(dest="what", required=True)
    add_label_studio_parsers(lsub)
