"""Ray's own TLS for its gRPC channels (GCS, raylets, object managers, workers, drivers): mutual TLS, every Ray
process presenting a certificate signed by one certificate authority and accepting only peers that do.

Ray turns it on from four environment variables, read by every Ray process (the C++ ``RayConfig`` and Python's
``ray._common.tls_utils.load_certs_from_env``): ``RAY_USE_TLS=1``, ``RAY_TLS_SERVER_CERT`` (this process's
certificate, PEM), ``RAY_TLS_SERVER_KEY`` (its private key) and ``RAY_TLS_CA_CERT`` (the authority that signed every
node's certificate); see docs.ray.io "TLS Authentication" (ray-core/configure.html#tls-authentication, checked for
Ray 2.60). They must be set for every ``ray start``, every worker (inherited from its raylet) and every driver,
``aerodaas run --address`` included; a process without them cannot talk to the cluster (its gRPC channel never
completes the handshake) and one with them cannot talk to a cluster without TLS.

:class:`RayTLS` holds the three files; :meth:`RayTLS.environ` gives the variables (what
:func:`use_tls` sets for this process and what it starts, as
:class:`aerodaas.clusters.local.LocalCluster` does for its nodes), :meth:`RayTLS.from_environ` reads them back (what
the address check before Ray, :func:`aerodaas.clusters.addresses.check_ray_address`, uses to speak TLS to a TLS
cluster), :meth:`RayTLS.client_context` is an :mod:`ssl` client context for that check.
"""
from __future__ import annotations

import os
import ssl
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

__all__ = ["RayTLS", "TLS_VARIABLES", "use_tls"]

#: the variables Ray reads (``RAY_USE_TLS`` turns TLS on; the other three name the files)
TLS_VARIABLES = ("RAY_USE_TLS", "RAY_TLS_SERVER_CERT", "RAY_TLS_SERVER_KEY", "RAY_TLS_CA_CERT")


@dataclass(frozen=True)
class RayTLS:
    """The files of Ray's mutual TLS: ``cert`` (this node's certificate, PEM, signed by ``ca``), ``key`` (its
    private key, PEM, unencrypted: Ray reads it without a passphrase) and ``ca`` (the authority's certificate, PEM).
    Construct it with :meth:`checked` to have the files checked."""

    cert: Path
    key: Path
    ca: Path

    @classmethod
    def checked(cls, cert: str | os.PathLike, key: str | os.PathLike, ca: str | os.PathLike,
                where: str = "RayTLS") -> "RayTLS":
        """The three files, each a readable regular file, the key readable and writable by its owner only
        (``chmod 600``, the rule of every key file of the project) and the certificate and key a matching pair whose
        chain ``ca`` verifies (loaded into an :mod:`ssl` context). Raises ValueError naming ``where``, the field and
        the file, never its content."""
        tls = cls(Path(cert), Path(key), Path(ca))
        for name, p in (("cert", tls.cert), ("key", tls.key), ("ca", tls.ca)):
            if not p.is_file() or not os.access(p, os.R_OK):
                raise ValueError(f"{where}.{name} {str(p)!r}: not a readable regular file")
        mode = tls.key.stat().st_mode & 0o077
        if mode:
            raise ValueError(f"{where}.key {str(tls.key)!r}: readable or writable by group or others (mode "
                             f"{tls.key.stat().st_mode & 0o777:o}); chmod 600 it")
        try:
            tls.client_context()
        except (ssl.SSLError, OSError) as e:
            raise ValueError(f"{where}: {str(tls.cert)!r}, {str(tls.key)!r}, {str(tls.ca)!r} are not a certificate, "
                             f"its key and an authority in PEM ({e})") from None
        return tls

    def environ(self) -> dict[str, str]:
        """The variables that turn Ray's TLS on with these files (absolute paths: Ray's processes start in other
        folders)."""
        return {"RAY_USE_TLS": "1", "RAY_TLS_SERVER_CERT": str(self.cert.resolve()),
                "RAY_TLS_SERVER_KEY": str(self.key.resolve()), "RAY_TLS_CA_CERT": str(self.ca.resolve())}

    @classmethod
    def from_environ(cls, env: Mapping[str, str] | None = None) -> "RayTLS | None":
        """Ray's TLS as ``env`` (default ``os.environ``) sets it: None when ``RAY_USE_TLS`` is unset or not 1/true
        (Ray's own test, ``ray._common.tls_utils``), else the files, checked with :meth:`checked`. Raises
        ValueError naming the variable that is missing or the file that is wrong."""
        env = os.environ if env is None else env
        if env.get("RAY_USE_TLS", "0").lower() not in ("1", "true"):
            return None
        missing = [v for v in TLS_VARIABLES[1:] if not env.get(v)]
        if missing:
            raise ValueError(f"RAY_USE_TLS={env['RAY_USE_TLS']} turns Ray's TLS on, but {', '.join(missing)} "
                             f"{'is' if len(missing) == 1 else 'are'} not set (Ray needs RAY_TLS_SERVER_CERT, "
                             f"RAY_TLS_SERVER_KEY and RAY_TLS_CA_CERT)")
        return cls.checked(env["RAY_TLS_SERVER_CERT"], env["RAY_TLS_SERVER_KEY"], env["RAY_TLS_CA_CERT"],
                           where="environment RAY_TLS_*")

    def client_context(self) -> ssl.SSLContext:
        """An :mod:`ssl` client context as a Ray process connects: it presents ``cert``/``key``, accepts a server
        whose certificate ``ca`` signed, and offers ALPN ``h2`` (gRPC runs over HTTP/2, RFC 7540 section 3.3). The
        host name is not checked (Ray's nodes may be addressed by IP addresses their certificates do not list;
        the authority is what is checked). Raises ssl.SSLError / OSError on unreadable or mismatched files."""
        ctx = ssl.create_default_context(ssl.Purpose.SERVER_AUTH, cafile=str(self.ca))
        ctx.check_hostname = False
        ctx.verify_mode = ssl.CERT_REQUIRED
        ctx.load_cert_chain(str(self.cert), str(self.key))
        ctx.set_alpn_protocols(["h2"])
        return ctx


def use_tls(tls: RayTLS | None) -> Callable[[], None]:
    """Set Ray's TLS variables for ``tls`` in this process's environment (None: leave the environment as it is),
    so that the Ray processes this process starts afterwards (nodes, their workers, drivers of ``aerodaas run``)
    inherit them and this process's own ``ray.init`` speaks TLS. Returns a function that puts back the values they
    had before (the pattern of :func:`aerodaas.clusters.loopback.loopback_only`)."""
    before = {v: os.environ.get(v) for v in TLS_VARIABLES}
    if tls is not None:
        os.environ.update(tls.environ())

    def restore() -> None:
        for v, old in before.items():
            if old is None:
                os.environ.pop(v, None)
            else:
                os.environ[v] = old

    return restore
