"""The state folder of ``aerodaas up``: where its cluster file, logs and warm driver's socket live. Standard library
only, so that the ``aerodaas`` command can find the warm driver before importing anything else."""
from __future__ import annotations

import os


def state_dir(environ: dict[str, str] | None = None) -> str:
    """``$AERODAAS_STATE_DIR`` of ``environ`` (default: this process's environment), else ``~/.aerodaas``."""
    env = os.environ if environ is None else environ
    return env.get("AERODAAS_STATE_DIR") or os.path.join(os.path.expanduser("~"), ".aerodaas")
