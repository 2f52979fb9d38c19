"""A real Label Studio server for the tests: the one ``tests/install-rig.sh`` installs in a venv of its own
(``AERODAAS_LABEL_STUDIO_VENV``, default ``~/.cache/aerodaas/label-studio-1.23.2``), started on loopback with its data
in the test's folder, a user and a legacy API token set at first start, local-files serving rooted at the test's
folder, and telemetry, error reporting and the version check off (the variables are Label Studio's own:
``label_studio/core/settings/base.py`` and ``label_studio.py``, read through ``get_env`` with or without the
``LABEL_STUDIO_`` prefix). The session fixture :func:`label_studio` starts it once and kills its process group."""
from __future__ import annotations

import os
import re
import secrets
import signal
import subprocess
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.conftest import skip_or_fail

VERSION = "1.23.2"
VENV = Path(os.environ.get("AERODAAS_LABEL_STUDIO_VENV",
                           Path.home() / ".cache" / "aerodaas" / f"label-studio-{VERSION}"))
#: the longest a first start (its database migrations) may take on a loaded machine before the tests give up
START_TIMEOUT_S = 600.0
_STARTED = re.compile(r"Starting development server at (http://127\.0\.0\.1:\d+)/")


@dataclass
class LabelStudioServer:
    """A running server: its ``url``, the user's legacy API ``token``, the local-files document ``root`` (frames
    folders go below it), its ``log`` file and process ``proc``."""

    url: str
    token: str
    root: Path
    log: Path
    proc: subprocess.Popen


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env(base: Path, root: Path) -> dict:
    keep = {k: v for k, v in os.environ.items() if k in ("PATH", "HOME", "LANG", "LC_ALL", "TMPDIR")}
    return {**keep, "LABEL_STUDIO_BASE_DATA_DIR": str(base / "data"),
            "LABEL_STUDIO_LOCAL_FILES_SERVING_ENABLED": "true", "LABEL_STUDIO_LOCAL_FILES_DOCUMENT_ROOT": str(root),
            "LABEL_STUDIO_COLLECT_ANALYTICS": "false", "LABEL_STUDIO_LATEST_VERSION_CHECK": "false",
            "LABEL_STUDIO_FEATURE_FLAGS_OFFLINE": "true", "SENTRY_DSN": "", "FRONTEND_SENTRY_DSN": "",
            "LABEL_STUDIO_SENTRY_DSN": "", "LABEL_STUDIO_FRONTEND_SENTRY_DSN": "",
            # an ML backend on loopback (aerodaas label serve): Label Studio refuses private addresses by default
            "LABEL_STUDIO_USE_DEFAULT_BANNED_SUBNETS": "false",
            "PYTHONUNBUFFERED": "1", "DJANGO_DEBUG": "false"}


def _healthy(url: str) -> bool:
    try:
        with urllib.request.urlopen(f"{url}/health", timeout=5) as r:
            return r.status == 200 and b"UP" in r.read(200)
    except OSError:
        return False


def start(base: Path, timeout: float = START_TIMEOUT_S, password: str | None = None) -> LabelStudioServer:
    """Start Label Studio with its data in ``base/data`` and its document root ``base/root``; wait (at most
    ``timeout`` seconds) until ``/health`` answers. ``password``: the user's (default: a random one, for a server
    only the API uses). Raises RuntimeError naming the log's tail if it does not."""
    exe = VENV / "bin" / "label-studio"
    if not exe.is_file():
        raise FileNotFoundError(f"no Label Studio at {exe} (run tests/install-rig.sh)")
    root = base / "root"
    root.mkdir(parents=True, exist_ok=True)
    token = secrets.token_hex(20)
    log = base / "label-studio.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen([str(exe), "start", "--no-browser", "--internal-host", "127.0.0.1",
                                 "--port", str(_free_port()), "--username", "reviewer@example.test",
                                 "--password", password or secrets.token_hex(12), "--user-token", token,
                                 "--enable-legacy-api-token"],
                                cwd=base, env=_env(base, root), stdout=out, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True)
    server = LabelStudioServer("", token, root, log, proc)
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            m = _STARTED.search(log.read_text(errors="replace"))  # the port it took (another if ours was taken)
            if m and _healthy(m.group(1)):
                server.url = m.group(1)
                return server
            time.sleep(1.0)
    except BaseException:  # interrupted while it starts: no server left behind
        stop(server)
        raise
    stop(server)
    raise RuntimeError(f"Label Studio did not answer /health within {timeout:.0f} s (exit code {proc.poll()}); "
                       f"log tail:\n{log.read_text(errors='replace')[-2000:]}")


def stop(server: LabelStudioServer) -> None:
    """Kill the server's process group (it started its own session) and reap it."""
    try:
        os.killpg(server.proc.pid, signal.SIGTERM)
        server.proc.wait(timeout=30)
    except ProcessLookupError:
        pass
    except subprocess.TimeoutExpired:
        os.killpg(server.proc.pid, signal.SIGKILL)
        server.proc.wait(timeout=30)


@pytest.fixture(scope="session")
def label_studio(tmp_path_factory):
    """A running :class:`LabelStudioServer` for the session (:func:`skip_or_fail` without the venv or when it does
    not start)."""
    if not (VENV / "bin" / "label-studio").is_file():
        skip_or_fail(f"Label Studio {VERSION} is not installed at {VENV} (run tests/install-rig.sh)")
    try:
        server = start(tmp_path_factory.mktemp("label_studio"))
    except (OSError, RuntimeError) as e:
        skip_or_fail(f"Label Studio did not start: {e}")
    yield server
    stop(server)
