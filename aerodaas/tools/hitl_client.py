"""The client of the human-in-the-loop API (``aerodaas inject``, tests, the reliability catalogue): where the running
server is, which token it takes, and the one request that carries it. Standard library only (no FastAPI).

A bearer token goes only where it was issued (docs/security.md, "The HITL API"):

* the token of the state file ``$AERODAAS_STATE_DIR/hitl.json`` (written by :class:`aerodaas.tools.hitl.HitlServer`)
  is sent only to the server that wrote it: the URL asked for must have the state file's origin (RFC 6454: the same
  scheme, the same host after normalising (lower case, no trailing dot, an IP address in its canonical form; no name
  resolution, so ``localhost`` and ``127.0.0.1`` are different hosts) and the same port, 80 / 443 when not
  written), and the process that wrote the file must still be running (a file left by a run that did not end
  cleanly names a port anyone may have taken since). Any other URL needs its own token (``--token`` or
  ``$AERODAAS_HITL_TOKEN``);
* a plain ``http`` URL whose host is not a loopback address (:func:`aerodaas.clusters.tls.is_loopback`) is refused,
  whatever the token's source, unless ``insecure_http`` (``aerodaas inject --insecure-http``) says to send the
  token in clear text anyway;
* only ``http`` and ``https`` URLs with a host are taken (``urllib`` would also open ``file:`` and ``ftp:``);
* a redirect is not followed (``urllib`` would repeat the ``Authorization`` header to wherever it points: the API
  never redirects), and no proxy of the environment is used for ``http`` (``http_proxy`` would receive the token in
  clear text; ``https`` goes through a proxy as a CONNECT tunnel, the TLS session ends at the server).

Every refusal is a ``ValueError`` naming the URL, where it came from and why, raised before any connection.
"""
from __future__ import annotations

import ipaddress
import json
import os
import ssl
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from aerodaas.clusters.tls import is_loopback, state_dir

__all__ = ["HitlTarget", "INJECT_VALUE_OPTIONS", "inject_argv", "origin", "request", "resolve_target", "state_file"]

#: the port of a URL that names none, per scheme (RFC 9110 sections 4.2.1 and 4.2.2)
DEFAULT_PORTS = {"http": 80, "https": 443}


def state_file() -> Path:
    """Where a running server publishes its url and token: ``$AERODAAS_STATE_DIR/hitl.json``
    (:func:`aerodaas.clusters.tls.state_dir`)."""
    return state_dir() / "hitl.json"


def origin(url: str, source: str = "--url") -> tuple[str, str, int]:
    """The origin ``(scheme, host, port)`` of an ``http``/``https`` URL (RFC 6454 section 4): scheme and host in
    lower case, the host without brackets or a trailing dot and, for an IP address, in its canonical form
    (``::0:1`` -> ``::1``); the port the scheme's default when not written. Raises ``ValueError`` naming ``source``
    and the URL when it is not ``http(s)://HOST[:PORT][/PATH]`` (another scheme, no host, user information, a bad
    port)."""
    try:
        p = urlsplit(url.strip())
        port = p.port
    except ValueError as e:
        raise ValueError(f"{source} {url!r} is not a URL ({e})") from None
    scheme = p.scheme.lower()
    if scheme not in DEFAULT_PORTS or not p.hostname:
        raise ValueError(f"{source} {url!r}: give http(s)://HOST[:PORT], the address of the HITL API")
    if p.username is not None or p.password is not None:
        raise ValueError(f"{source} {url!r}: user information in the URL is not taken (the API's token goes in "
                         f"$AERODAAS_HITL_TOKEN)")
    host = p.hostname.rstrip(".")
    try:
        host = ipaddress.ip_address(host).compressed
    except ValueError:
        pass
    return scheme, host, port if port is not None else DEFAULT_PORTS[scheme]


@dataclass(frozen=True)
class HitlTarget:
    """Where a request goes and what it carries: ``url``, ``token`` (left out of ``repr``), ``cafile`` (the
    certificate to trust for ``https``; None: the system's CAs) and ``from_state`` (the token is the state file's)."""

    url: str
    token: str = field(repr=False)
    cafile: str | None = None
    from_state: bool = False


def _running(pid: Any) -> bool:
    """Whether process ``pid`` (an int > 0) is running on this machine."""
    if not isinstance(pid, int) or isinstance(pid, bool) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, under another user
        return True
    return True


def _read_state(f: Path) -> dict:
    """The state file ``f`` of a running server: ``url``, ``token`` and ``pid`` of a process still running. Raises
    RuntimeError when there is none, ValueError when the file is not one or its writer is gone."""
    if not f.is_file():
        raise RuntimeError(f"no HITL server found: give --url and the server's token ($AERODAAS_HITL_TOKEN or "
                           f"--token), set AERODAAS_HITL_URL, or start a run with hitl enabled (writes {f})")
    try:
        info = json.loads(f.read_text())
        ok = isinstance(info, dict) and isinstance(info.get("url"), str) and isinstance(info.get("token"), str)
    except (OSError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"{f} is not a HITL state file (url and token)")
    if not _running(info.get("pid")):
        raise ValueError(f"{f} was written by process {info.get('pid')!r}, which is not running (a run that did not "
                         f"end cleanly): its server is gone and its token is not sent to whatever listens at "
                         f"{info['url']} now; delete the file, or give --url and that server's token")
    return info


def resolve_target(url: str | None = None, token: str | None = None, cafile: str | None = None,
                   insecure_http: bool = False) -> HitlTarget:
    """The request's :class:`HitlTarget` by the rules of the module docstring. ``url``, ``token``, ``cafile``: given
    (``--url``, ``--token``, ``--cacert``), else ``$AERODAAS_HITL_URL``, ``$AERODAAS_HITL_TOKEN``,
    ``$AERODAAS_HITL_CAFILE``, else the state file's (its token only for its own origin, its ``cafile`` for its
    origin too). Raises ``ValueError`` (a URL refused, the state file's token asked for another server) and
    RuntimeError (no server known), before any connection."""
    url_source = "--url" if url else "$AERODAAS_HITL_URL"
    url = url or os.environ.get("AERODAAS_HITL_URL") or None
    token = token or os.environ.get("AERODAAS_HITL_TOKEN") or None
    cafile = cafile or os.environ.get("AERODAAS_HITL_CAFILE") or None
    from_state = False
    if url is not None:
        asked = origin(url, url_source)
    if token is None or url is None:
        f = state_file()
        info = _read_state(f)
        issued = origin(info["url"], f"the url of {f}")
        if url is None:
            url, url_source, asked = info["url"], f"the url of {f}", issued
        if token is None:
            if asked != issued:
                raise ValueError(f"{url_source} {url!r} is not the server that issued the token in {f} "
                                 f"({info['url']}; the same scheme, host and port are required): that token is "
                                 f"sent only there. Give this server's own token in $AERODAAS_HITL_TOKEN "
                                 f"(or --token)")
            token, from_state = info["token"], True
        if asked == issued:
            cafile = cafile or info.get("cafile") or None
    if asked[0] == "http" and not is_loopback(asked[1]) and not insecure_http:
        raise ValueError(f"{url_source} {url!r}: plain http to {asked[1]!r}, which is not a loopback address, would "
                         f"send the bearer token in clear text over the network: use the server's https URL "
                         f"(its --tls-cert), or --insecure-http to send it in clear text anyway")
    return HitlTarget(url, token, cafile, from_state)


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    """Follow no redirect: the 3xx answer is returned as an ``HTTPError`` (the token stays where it was issued)."""

    def redirect_request(self, req, fp, code, msg, headers, newurl):  # noqa: ANN001 - urllib's signature
        return None


def _opener(target: HitlTarget) -> urllib.request.OpenerDirector:
    """urllib with no redirects, no proxy for ``http``, and for ``https`` a context verifying the certificate and
    host name against ``target.cafile`` (else the system's CAs)."""
    proxies = {k: v for k, v in urllib.request.getproxies().items() if k == "https"}
    handlers: list = [urllib.request.ProxyHandler(proxies), _NoRedirect()]
    if target.url.lower().startswith("https:"):
        handlers.append(urllib.request.HTTPSHandler(context=ssl.create_default_context(cafile=target.cafile)))
    return urllib.request.build_opener(*handlers)


def request(method: str, path: str, body: Any = None, url: str | None = None, token: str | None = None,
            timeout: float = 10.0, cafile: str | None = None, insecure_http: bool = False) -> tuple[int, Any]:
    """Minimal client (stdlib only): returns (HTTP status, decoded JSON). The server, token and certificate to trust
    are :func:`resolve_target`'s. An ``https`` URL is verified (certificate and host name). Raises ``ValueError``
    when the target is refused (module docstring) and RuntimeError when no server can be found or reached (a
    certificate that does not verify included)."""
    target = resolve_target(url, token, cafile, insecure_http)
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(target.url.rstrip("/") + path, data=data, method=method,
                                 headers={"Authorization": f"Bearer {target.token}",
                                          "Content-Type": "application/json"})
    try:
        with _opener(target).open(req, timeout=timeout) as r:
            return r.status, json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        raw = e.read()
        try:
            return e.code, json.loads(raw)
        except ValueError:
            return e.code, raw.decode(errors="replace")
    except urllib.error.URLError as e:
        raise RuntimeError(f"cannot reach the HITL API at {target.url}: {e.reason}") from None


#: options of ``aerodaas inject`` whose value may start with '-': a bearer token (base64url: one in 64 starts so), a
#: waypoint west or south of home (``-3,2,5``)
INJECT_VALUE_OPTIONS = ("--drone", "--waypoint", "--index", "--priority", "--url", "--token", "--cacert")


def inject_argv(argv: list[str]) -> list[str]:
    """``aerodaas`` command-line ``argv`` with, for the ``inject`` command, each ``OPTION VALUE`` of
    :data:`INJECT_VALUE_OPTIONS` written ``OPTION=VALUE``: argparse reads a separate value that starts with '-' as an
    option of its own (``--token -abc...`` failed with "expected one argument"). Other commands are left as given."""
    if argv[:1] != ["inject"]:
        return argv
    out, i = [], 0
    while i < len(argv):
        if argv[i] in INJECT_VALUE_OPTIONS and i + 1 < len(argv):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out
