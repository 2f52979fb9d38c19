"""A small client of Label Studio's REST API (plain ``urllib``): what ``aerodaas label push`` and ``pull`` call.

The token goes to the ``url`` given and nowhere else: no proxy is used, redirects are refused (urllib would carry
the ``Authorization`` header to wherever a redirect points), and an absolute URL in a task is fetched only on the
same scheme, host and port. Plain ``http`` is refused to a host other than loopback unless ``insecure_http``
(the project's rule: a credential goes only where it was issued, and off loopback over TLS).

Authentication (Label Studio 1.23, ``label_studio/jwt_auth``): a personal access token (a JWT refresh token) is
exchanged at ``/api/token/refresh/`` for an access token sent as ``Authorization: Bearer``; any other token is a
legacy token, sent as ``Authorization: Token`` (the server's organisation must allow legacy tokens).
"""
from __future__ import annotations

import json
import os
import urllib.error
import urllib.request
from pathlib import Path
from urllib.parse import urlencode, urljoin, urlsplit

from aerodaas.clusters.tls import is_loopback

__all__ = ["LabelStudio", "LabelStudioError", "check_url", "read_token"]

#: seconds a request may take before Label Studio counts as not answering (an export of thousands of tasks is built
#: while the request waits, so this is generous)
DEFAULT_TIMEOUT_S = 60.0
#: the largest response read (bytes): an export or an image larger than this is refused, not read into memory
MAX_RESPONSE_BYTES = 1 << 30
#: the largest token file read (bytes)
MAX_TOKEN_BYTES = 16384


class LabelStudioError(ValueError):
    """Label Studio cannot be used as asked (not answering, a refused token, an unknown project, a request it
    refused, a bad URL): the message is one line naming the thing and the value."""


def check_url(url: str, insecure_http: bool = False) -> str:
    """``url`` without a trailing slash, once it is an ``http(s)://host[:port][/path]`` URL whose plain ``http`` goes
    only to loopback (or ``insecure_http``). Raises :class:`LabelStudioError` naming the value."""
    parts = urlsplit(url)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise LabelStudioError(f"--url {url!r}: expected http(s)://HOST[:PORT] of the Label Studio server")
    if parts.query or parts.fragment or parts.username or parts.password:
        raise LabelStudioError(f"--url {url!r}: give the server's address only (no query, fragment or user)")
    if parts.scheme == "http" and not is_loopback(parts.hostname) and not insecure_http:
        raise LabelStudioError(f"--url {url!r}: plain http to a host other than loopback would send the token "
                               f"unencrypted; use https, or --insecure-http on a network you trust")
    return url.rstrip("/")


def read_token(token_file: Path | None, token: str | None) -> str:
    """The Label Studio API token: the stripped content of ``token_file`` (at most :data:`MAX_TOKEN_BYTES` read),
    else ``token``, else the environment's ``LABEL_STUDIO_API_KEY``. Raises :class:`LabelStudioError` naming the
    file (unreadable, larger than a token) or saying how to give a token when there is none."""
    if token_file is not None:
        try:
            with open(token_file, "rb") as f:
                raw = f.read(MAX_TOKEN_BYTES + 1)
        except OSError as e:
            raise LabelStudioError(f"--token-file {str(token_file)!r}: cannot be read ({e.strerror})") from None
        if len(raw) > MAX_TOKEN_BYTES:
            raise LabelStudioError(f"--token-file {str(token_file)!r}: larger than {MAX_TOKEN_BYTES} bytes, "
                                   f"not a token")
        return raw.decode("utf-8", "replace").strip()
    token = token or os.environ.get("LABEL_STUDIO_API_KEY", "")
    if not token:
        raise LabelStudioError("token: give --token-file F (or --token T, or LABEL_STUDIO_API_KEY)")
    return token


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, req, fp, code, msg, headers, newurl):  # noqa: D102 - urllib's hook
        raise urllib.error.HTTPError(req.full_url, code, f"redirect to {newurl} refused (the token stays with "
                                                         f"the server it was given for)", headers, fp)


def _is_jwt(token: str) -> bool:
    parts = token.split(".")
    return len(parts) == 3 and token.startswith("eyJ") and all(parts)


class LabelStudio:
    """One Label Studio server at ``url`` (checked by :func:`check_url`) used with ``token``; each request waits at
    most ``timeout`` seconds. Methods raise :class:`LabelStudioError`."""

    def __init__(self, url: str, token: str, *, timeout: float = DEFAULT_TIMEOUT_S, insecure_http: bool = False):
        self.url = check_url(url, insecure_http)
        token = token.strip()
        if not token or any(c.isspace() for c in token):
            raise LabelStudioError("token: empty or holds white space (give the token from Label Studio's "
                                   "Account & Settings page)")
        self._token = token
        self._auth: str | None = None
        self.timeout = timeout
        self._opener = urllib.request.build_opener(urllib.request.ProxyHandler({}), _NoRedirect())

    # -- requests ------------------------------------------------------------------------------------------------
    def _full(self, path: str) -> str:
        """The absolute URL of ``path`` (``/api/...``, or an absolute URL on this server's origin)."""
        full = urljoin(self.url + "/", path.lstrip("/")) if not urlsplit(path).scheme else path
        a, b = urlsplit(full), urlsplit(self.url)
        if (a.scheme, a.hostname, a.port) != (b.scheme, b.hostname, b.port):
            raise LabelStudioError(f"url {path!r} is not on the Label Studio server {self.url}: the token is not "
                                   f"sent there")
        return full

    def _send(self, method: str, path: str, body: object = None, headers: dict | None = None) -> bytes:
        req = urllib.request.Request(self._full(path), method=method, headers=dict(headers or {}))
        if body is not None:
            req.data = json.dumps(body).encode()
            req.add_header("Content-Type", "application/json")
        try:
            with self._opener.open(req, timeout=self.timeout) as r:
                data = r.read(MAX_RESPONSE_BYTES + 1)
        except urllib.error.HTTPError as e:
            raise self._http_error(method, path, e) from None
        except (urllib.error.URLError, TimeoutError, ConnectionError, OSError) as e:
            reason = getattr(e, "reason", e)
            raise LabelStudioError(f"url={self.url!r}: Label Studio does not answer ({reason})") from None
        if len(data) > MAX_RESPONSE_BYTES:
            raise LabelStudioError(f"{method} {path}: response larger than {MAX_RESPONSE_BYTES} bytes, refused")
        return data

    def _http_error(self, method: str, path: str, e: urllib.error.HTTPError) -> LabelStudioError:
        if 300 <= e.code < 400:
            return LabelStudioError(f"{method} {path}: HTTP {e.code} {e.reason}")
        try:
            doc = json.loads(e.read(65536) or b"{}")
            detail = doc.get("validation_errors") or doc.get("detail") or doc
        except (ValueError, AttributeError, OSError):
            detail = e.reason
        if e.code in (401, 403):
            return LabelStudioError(f"token: refused by Label Studio at {self.url} (HTTP {e.code}: {detail})")
        return LabelStudioError(f"{method} {path}: Label Studio answered HTTP {e.code}: {detail}")

    def _authorization(self) -> str:
        if self._auth is None:
            if _is_jwt(self._token):  # a personal access token: exchange it for a short-lived access token
                doc = json.loads(self._send("POST", "/api/token/refresh/", {"refresh": self._token}))
                self._auth = f"Bearer {doc['access']}"
            else:
                self._auth = f"Token {self._token}"
        return self._auth

    def request(self, method: str, path: str, body: object = None, query: dict | None = None) -> object:
        """The JSON answer of ``method`` ``path`` (``/api/...``) with the JSON ``body`` and the ``query``
        parameters, authenticated. Raises :class:`LabelStudioError` (not answering, HTTP error, not JSON)."""
        if query:
            path = f"{path}?{urlencode(query, doseq=True)}"
        data = self._send(method, path, body, {"Authorization": self._authorization(), "Accept": "application/json"})
        if not data:
            return None
        try:
            return json.loads(data)
        except ValueError:
            raise LabelStudioError(f"{method} {path}: Label Studio's answer is not JSON: {data[:80]!r}") from None

    def download(self, path: str) -> bytes:
        """The bytes at ``path`` (a ``/data/...`` URL of a task, or an export), authenticated."""
        return self._send("GET", path, headers={"Authorization": self._authorization()})

    # -- the API calls of push and pull ----------------------------------------------------------------------------
    def whoami(self) -> dict:
        """The token's user (``/api/current-user/whoami``): checks the server answers and accepts the token."""
        return self.request("GET", "/api/current-user/whoami")

    def projects_titled(self, title: str) -> list[dict]:
        """The projects whose title is exactly ``title`` (the list is searched page by page, at most 100 pages)."""
        found = []
        for page in range(1, 101):
            try:
                doc = self.request("GET", "/api/projects", query={"title": title, "page": page, "page_size": 100})
            except LabelStudioError as e:
                if "HTTP 404" in str(e):  # past the last page
                    break
                raise
            results = doc.get("results", []) if isinstance(doc, dict) else doc
            found += [p for p in results if p.get("title") == title]
            if not isinstance(doc, dict) or not doc.get("next"):
                break
        return found

    def project(self, ref: str) -> dict:
        """The project with id ``ref`` (digits) or title ``ref``. Raises :class:`LabelStudioError` when there is
        none, or several with that title."""
        if ref.isdigit():
            try:
                return self.request("GET", f"/api/projects/{int(ref)}")
            except LabelStudioError as e:
                if "HTTP 404" in str(e):
                    raise LabelStudioError(f"--project {ref}: no project with that id at {self.url}") from None
                raise
        found = self.projects_titled(ref)
        if not found:
            raise LabelStudioError(f"--project {ref!r}: no project with that title at {self.url}")
        if len(found) > 1:
            raise LabelStudioError(f"--project {ref!r}: {len(found)} projects have that title "
                                   f"(ids {[p['id'] for p in found]}): give the id")
        return found[0]

    def project_url(self, project_id: int) -> str:
        """The address of a project's task list in Label Studio's web interface."""
        return f"{self.url}/projects/{project_id}/data"
