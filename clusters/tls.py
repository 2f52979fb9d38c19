"""TLS for the servers AeroDaaS opens to people (the HITL API, the Foxglove live view of a run or a replay, and any
server added later): the certificate and key files, and the one exposure rule, applied by each server's constructor
and, before Ray starts, by its command.

A server bound to a loopback address (``127.0.0.0/8``, ``::1``, ``localhost``) is reachable only from this machine
and may serve plain HTTP/WS without a token. Bound to any other address it needs a token that clients present (at
least :data:`MIN_TOKEN_CHARS` characters) and a certificate and a key (it then serves HTTPS/WSS with Python's
:mod:`ssl`: TLS 1.2 or later, OpenSSL's default ciphers), or, in place of the certificate only, an explicit
``insecure`` choice (the ``--insecure`` flag, ``hitl.insecure``, ``ServeAccess(insecure=True)``), which the server
exposes (``insecure``) and the run summary repeats. :func:`check_exposure` is that rule, the only one: a server calls
it (through :meth:`ServeAccess.check` when it holds a :class:`ServeAccess`) in its constructor, before it binds,
and its command calls it again before Ray starts, so the error names the command's flags. :func:`check_tls_files`
checks the files: a regular file each, readable, the certificate PEM (a chain may follow),
the key PEM, unencrypted, matching the certificate, and readable or writable by its owner only (``chmod 600``; the
rule of the MAVLink signing key file, :mod:`aerodaas.backends.mavlink.signing`). Every error is a ``ValueError``
naming the field (or flag) and the file, never its content.
"""
from __future__ import annotations

import ipaddress
import json
import os
import ssl
import stat
from dataclasses import dataclass, field
from pathlib import Path
import tempfile

__all__ = ["MIN_TOKEN_CHARS", "ServeAccess", "check_exposure", "check_tls_files", "is_loopback", "server_context",
           "state_dir", "write_private_json"]


#: the shortest token a server off loopback may ask of its clients (16 random base64url characters: 96 bits)
MIN_TOKEN_CHARS = 16


def state_dir() -> Path:
    """Where a running server hands its connection (url, token) to the clients of this user:
    ``$AERODAAS_STATE_DIR``, default ``~/.aerodaas``."""
    return Path(os.environ.get("AERODAAS_STATE_DIR", Path.home() / ".aerodaas"))


def write_private_json(path: Path, data: dict) -> None:
    """Write ``data`` as JSON to ``path`` readable and writable by its owner only (0600), whatever was there before:
    written to a new file created 0600 (never wider, not even for a moment), then renamed over ``path``. The
    folder is created 0700 when missing. Raises OSError."""
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)  # mkstemp creates it 0600
    try:
        with os.fdopen(fd, "w") as fh:
            json.dump(data, fh)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address, or ``localhost``) is a loopback address: only this machine can reach it.
    A host name other than ``localhost`` is not (it may resolve to any address)."""
    h = host.strip().strip("[]")
    if h.lower() in ("localhost", "localhost."):
        return True
    try:
        return ipaddress.ip_address(h).is_loopback
    except ValueError:
        return False


class _Encrypted(ssl.SSLError):
    pass


def _no_password() -> bytes:
    """The key's passphrase callback: an encrypted key is refused (OpenSSL would otherwise ask on the terminal)."""
    raise _Encrypted("the key is encrypted")


def check_tls_files(cert: str, key: str, cert_field: str, key_field: str) -> None:
    """Check a certificate file ``cert`` and its private key file ``key`` (PEM) as :func:`server_context` will load
    them. Raises ``ValueError`` naming ``cert_field`` / ``key_field`` and the path when a file is missing, not a
    regular file or unreadable, when the certificate is not a PEM certificate, when the key is readable or writable
    by the group or others (mode ``& 0o077``), encrypted, not a PEM key or not the certificate's."""
    for f, name in ((cert, cert_field), (key, key_field)):
        try:
            st = os.stat(f)
        except OSError as e:
            raise ValueError(f"{name}: {f!r}: {e.strerror or e}") from None
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(f"{name}: {f!r} is not a regular file")
        if not os.access(f, os.R_OK):
            raise ValueError(f"{name}: {f!r} is not readable by this user")
    mode = stat.S_IMODE(os.stat(key).st_mode)
    if mode & 0o077:
        raise ValueError(f"{key_field}: {key!r} is readable or writable by other users (mode {mode:04o}); "
                         f"a private key must be the owner's only: chmod 600 {key}")
    probe = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    try:
        probe.load_verify_locations(cafile=cert)
    except (ssl.SSLError, ValueError) as e:
        raise ValueError(f"{cert_field}: {cert!r} is not a PEM certificate ({e})") from None
    try:
        server_context(cert, key)
    except _Encrypted:
        raise ValueError(f"{key_field}: {key!r} is encrypted; give an unencrypted key (readable by its owner "
                         f"only) or decrypt it: openssl pkey -in {key} -out plain.key") from None
    except ssl.SSLError as e:
        raise ValueError(f"{key_field}: {key!r} is not a PEM private key of the certificate {cert!r} "
                         f"({e.reason or e})") from None


def server_context(cert: str, key: str) -> ssl.SSLContext:
    """A server-side :class:`ssl.SSLContext` (TLS 1.2 or later) holding the certificate chain ``cert`` and its key
    ``key`` (PEM files). Raises ``ssl.SSLError`` for files OpenSSL refuses (:func:`check_tls_files` first)."""
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    ctx.load_cert_chain(cert, key, password=_no_password)
    return ctx


@dataclass(frozen=True)
class ServeAccess:
    """How a server of the run is reached: TLS files (``cert_file`` and ``key_file``, PEM, both or neither), the
    token a client must present (None: none needed) and ``insecure`` (plain text off loopback, chosen explicitly).
    The token is left out of ``repr`` so that a log of this object does not carry it."""

    cert_file: str | None = None
    key_file: str | None = None
    token: str | None = field(default=None, repr=False)
    insecure: bool = False

    @property
    def tls(self) -> bool:
        return self.cert_file is not None

    def context(self) -> ssl.SSLContext | None:
        """The server's TLS context, None without TLS."""
        return server_context(self.cert_file, self.key_file) if self.cert_file and self.key_file else None

    def check(self, host: str, where: str, cert_field: str = "ServeAccess.cert_file",
              key_field: str = "ServeAccess.key_file", insecure_field: str = "ServeAccess(insecure=True)",
              token_field: str = "ServeAccess.token") -> None:
        """:func:`check_exposure` for a server ``where`` bound to ``host`` with this access: what a server's
        constructor calls before it binds. Raises ``ValueError`` naming the field and the value."""
        check_exposure(host, self.cert_file, self.key_file, self.insecure, where, cert_field, key_field,
                       insecure_field, token=self.token, token_field=token_field)

    def clear_text_off_loopback(self, host: str) -> bool:
        """Whether a server bound to ``host`` with this access serves in clear text off loopback (allowed only by
        ``insecure``): what a run summary or a server's ``insecure`` attribute repeats."""
        return self.insecure and not self.tls and not is_loopback(host)


def check_exposure(host: str, cert: str | None, key: str | None, insecure: bool, where: str,
                   cert_field: str = "--tls-cert", key_field: str = "--tls-key", insecure_field: str = "--insecure",
                   *, token: str | bool | None = True, token_field: str = "a token") -> None:
    """The exposure rule of the module docstring for a server ``where`` (e.g. ``"--live"``, ``"LiveServer"``) bound
    to ``host``, the one every server of AeroDaaS applies: a certificate ``cert`` without its key ``key`` (or the
    reverse) is refused; given, both are checked (:func:`check_tls_files`); off loopback, neither given nor
    ``insecure`` is refused, and so is a server whose clients present no token, ``insecure`` or not. ``token``: the
    token the server asks for (a string of at least :data:`MIN_TOKEN_CHARS` characters), None when it asks for
    none, True when it will generate one (a command's check before the server exists). ``*_field``: the names the
    message gives the caller's flags or parameters. Raises ``ValueError`` naming the field or flag and the value,
    never the token."""
    if (cert is None) != (key is None):
        given, missing = (cert_field, key_field) if cert is not None else (key_field, cert_field)
        raise ValueError(f"{given} is given without {missing}: TLS needs both the certificate and its key")
    if cert is not None and key is not None:
        check_tls_files(cert, key, cert_field, key_field)
    if is_loopback(host):
        return
    if cert is None and not insecure:
        raise ValueError(f"{where}: {host!r} is not a loopback address and no TLS certificate is given: give "
                         f"{cert_field} and {key_field} (served over TLS), bind 127.0.0.1, or accept clear text "
                         f"off this machine with {insecure_field}")
    if token is not True and (not isinstance(token, str) or len(token) < MIN_TOKEN_CHARS):
        what = "no token" if not token else f"a token shorter than {MIN_TOKEN_CHARS} characters"
        raise ValueError(f"{where}: {host!r} is not a loopback address and its clients would present {what}: give "
                         f"{token_field} (at least {MIN_TOKEN_CHARS} characters, e.g. secrets.token_urlsafe(32)), "
                         f"or bind 127.0.0.1")
