"""An ``aerodaas run --live`` or ``aerodaas replay --live`` run in the test's own process
(:func:`tests.inputs.cli_inprocess.run_cli`) with a live-view client connected from another thread.

The command holds the calling thread (``run_cli`` puts signal handlers back, which only the main thread may do), so
the client runs on a thread of its own. It learns the live view's URL from the command's owner-only state file
``$AERODAAS_STATE_DIR/live.json`` (:func:`aerodaas.liveview.server.write_live_state`), which a run or a replay
writes whenever its live view has a token: the caller sets ``AERODAAS_LIVE_TOKEN`` on loopback (off loopback one is
generated). A run on the pytest worker's shared Ray session pays neither an interpreter, the CLI's imports nor a Ray
of its own."""
from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from tests.inputs.cli_inprocess import CliResult, run_cli

__all__ = ["LiveRun", "run_with_live_client"]


@dataclass
class LiveRun:
    """What :func:`run_with_live_client` returns: the command's ``cli`` result, the ``info`` read from live.json
    (``url``, ``token``, ``url_with_token``, ``cafile``; None if it never appeared), what the client returned
    (``got``, None when it failed) and the client's exception (``error``)."""

    cli: CliResult
    info: dict | None
    got: Any
    error: BaseException | None


def run_with_live_client(args: list[str], env: dict, client: Callable[[str], Any], shared_ray: bool = True,
                         cwd: Path | str | None = None, join_s: float = 360.0) -> LiveRun:
    """``aerodaas ARGS`` in-process with ``env`` (which sets ``AERODAAS_STATE_DIR``, and ``AERODAAS_LIVE_TOKEN`` on
    loopback); ``client(url_with_token)`` is called on a thread once live.json is there, and its return value kept.
    ``shared_ray``: a ``run`` on the worker's shared Ray session (the caller requests ``ray_session``); False for a
    ``replay``, which never starts Ray; ``cwd``: the command's working folder (default: the current one). The thread is given ``join_s`` wall seconds after the command returns (the
    client stops by itself once the server closes). Raises ``ValueError`` when live.json is there before the
    command (an earlier command's)."""
    state = Path(env["AERODAAS_STATE_DIR"]) / "live.json"
    if state.exists():  # an earlier command's: the client would connect to a server that is gone
        raise ValueError(f"{state} is there before the command: give each command a state folder of its own")
    out: dict[str, Any] = {"info": None, "got": None, "error": None}
    done = threading.Event()

    def connect() -> None:
        try:
            while not state.is_file():
                if done.wait(0.05):
                    raise AssertionError(f"the command ended without writing {state}")
            time.sleep(0.05)  # written whole by write_private_json; read once it is there
            out["info"] = json.loads(state.read_text())
            out["got"] = client(out["info"]["url_with_token"])
        except BaseException as e:  # noqa: BLE001 - handed to the test, which reports it
            out["error"] = e

    th = threading.Thread(target=connect, daemon=True)
    th.start()
    try:
        cli = run_cli(*args, cwd=cwd, env=env, shared_ray=shared_ray)
    finally:
        done.set()
        th.join(timeout=join_s)
    return LiveRun(cli, out["info"], out["got"], out["error"])
