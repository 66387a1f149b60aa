"""OPC UA security on both sides: Basic256Sha256 Sign & Encrypt with certificates, and user name / password.

Each side keeps, in its data directory's ``opcua/`` folder (:func:`twin.furnace.opcua.options.certificate_dir`):

* its own self-signed application certificate ``<role>-cert.der`` and key ``<role>-key.pem`` (role
  ``twin``, ``emulator``, or ``results``: the twin's own results server), created on first use
  (:func:`ensure_identity`);
* ``trusted/``: the peer certificates it accepts.  Neither side trusts a certificate it was not given:
  copy the emulator's ``emulator-cert.der`` into the twin's ``opcua/trusted/`` and the twin's
  ``twin-cert.der`` into the emulator's (a real furnace: into its server's trust list).

User names and passwords travel only inside the encrypted channel (or on loopback).

Example
-------
>>> import tempfile
>>> ident = ensure_identity(tempfile.mkdtemp(), "twin")
>>> ident.cert.name, ident.key.name, ident.cert.stat().st_size > 500
('twin-cert.der', 'twin-key.pem', True)
"""

from __future__ import annotations

import contextlib
import fcntl
import ipaddress
import logging
import os
import socket
import tempfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from asyncua.server.user_managers import UserManager

log = logging.getLogger(__name__)

Role = Literal["twin", "emulator", "results"]
APPLICATION_URI: dict[str, str] = {"twin": "urn:furnace-twin:twin", "emulator": "urn:furnace-twin:emulator",
                                   "results": "urn:furnace-twin:results"}
CERT_DAYS = 3650
SESSION_TIMEOUT_MS = 600_000  # what servers commonly grant (asyncua asks for an hour and warns when revised)


@dataclass(frozen=True)
class Identity:
    """An application's certificate (DER) and private key (PEM)."""

    cert: Path
    key: Path


def trusted_dir(cert_dir: str | Path) -> Path:
    """The folder of peer certificates a side accepts."""
    return Path(cert_dir) / "trusted"


@contextlib.contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """An exclusive lock on the folder, so that two processes starting at once create one identity."""
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".lock", "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _write_atomic(path: Path, data: bytes, mode: int) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".")
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _alt_names(role: Role, hosts: tuple[str, ...]) -> list[Any]:
    from cryptography import x509

    names: list[Any] = [x509.UniformResourceIdentifier(APPLICATION_URI[role])]
    for h in dict.fromkeys((socket.gethostname(), "localhost", *hosts)):
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            names.append(x509.DNSName(h))
    return names


def ensure_identity(cert_dir: str | Path, role: Role, hosts: tuple[str, ...] = ("127.0.0.1",)) -> Identity:
    """This side's certificate and key in ``cert_dir``, created (self-signed, RSA 2048, SHA-256) if absent."""
    from asyncua.crypto.cert_gen import (
        dump_private_key_as_pem,
        generate_private_key,
        generate_self_signed_app_certificate,
    )
    from cryptography.hazmat.primitives.serialization import Encoding
    from cryptography.x509.oid import ExtendedKeyUsageOID

    folder = Path(cert_dir)
    ident = Identity(cert=folder / f"{role}-cert.der", key=folder / f"{role}-key.pem")
    with _locked(folder):
        if ident.cert.is_file() and ident.key.is_file():
            return ident
        key = generate_private_key()
        usage = ExtendedKeyUsageOID.CLIENT_AUTH if role == "twin" else ExtendedKeyUsageOID.SERVER_AUTH
        cert = generate_self_signed_app_certificate(
            key, f"furnace-twin {role}", {"organizationName": "furnace-twin"}, _alt_names(role, hosts),
            extended=[usage, ExtendedKeyUsageOID.CLIENT_AUTH, ExtendedKeyUsageOID.SERVER_AUTH], days=CERT_DAYS)
        _write_atomic(ident.key, dump_private_key_as_pem(key), 0o600)
        _write_atomic(ident.cert, cert.public_bytes(Encoding.DER), 0o644)
        trusted_dir(folder).mkdir(exist_ok=True)
        log.info("created the OPC UA certificate %s (valid %d days); the peer must trust it: copy it into "
                 "its opcua/trusted/ folder", ident.cert, CERT_DAYS)
    return ident


def rejected_dir(cert_dir: str | Path) -> Path:
    """Where a side keeps the peer certificates it refused (to inspect, and move into ``trusted/``)."""
    return Path(cert_dir) / "rejected"


class TrustedPeers:
    """A certificate check (asyncua's ``certificate_validator``): the peer's certificate must be valid now,
    name the peer's application URI and be one of the certificates in ``trusted/`` (re-read at every
    connection, so a copied certificate counts without a restart).  A refused certificate is saved in
    ``rejected/`` (its SHA-1 thumbprint as the name); ``refused`` is (that file, its subject) until the next
    check."""

    def __init__(self, cert_dir: str | Path, peer: Literal["client", "server"]) -> None:
        self.folder = trusted_dir(cert_dir)
        self.rejected = rejected_dir(cert_dir)
        self.peer = peer
        self.refused: tuple[Path | None, str] | None = None

    def _refuse(self, cert: Any) -> None:
        from cryptography.hazmat.primitives import hashes
        from cryptography.hazmat.primitives.serialization import Encoding

        subject = cert.subject.rfc4514_string()
        saved: Path | None = self.rejected / f"{cert.fingerprint(hashes.SHA1()).hex()}.der"
        try:
            self.rejected.mkdir(parents=True, exist_ok=True)
            _write_atomic(saved, cert.public_bytes(Encoding.DER), 0o644)  # type: ignore[arg-type]
        except OSError:
            saved = None
        self.refused = (saved, subject)

    async def __call__(self, cert: Any, app_description: Any) -> None:
        self.refused = None
        try:
            await self._check(cert, app_description)
        except BaseException:
            self._refuse(cert)
            raise

    async def _check(self, cert: Any, app_description: Any) -> None:
        from asyncua import ua
        from asyncua.common.utils import ServiceError
        from asyncua.crypto.truststore import TrustStore
        from asyncua.crypto.validator import CertificateValidator
        from asyncua.crypto.validator import CertificateValidatorOptions as Opt

        self.folder.mkdir(parents=True, exist_ok=True)
        if not any(p.suffix.lower() in (".der", ".pem", ".crt") for p in self.folder.iterdir()):
            log.warning("refused the %s certificate %s: %s holds no trusted certificate",
                        self.peer, cert.subject.rfc4514_string(), self.folder)
            raise ServiceError(ua.StatusCodes.BadCertificateUntrusted)
        store = TrustStore([self.folder], [])
        await store.load()
        peer = Opt.PEER_CLIENT if self.peer == "client" else Opt.PEER_SERVER
        options = Opt.TIME_RANGE | Opt.URI | Opt.TRUSTED | peer
        try:
            await CertificateValidator(options, store).validate(cert, app_description)
        except ServiceError:
            log.warning("refused the %s certificate %s (not in %s, expired, or not for %s)", self.peer,
                        cert.subject.rfc4514_string(), self.folder, app_description.ApplicationUri)
            raise


async def secure_client(client: Any, *, security: str, cert_dir: str | Path, username: str | None,
                        password: str | None) -> None:
    """Configure an ``asyncua.Client`` of the twin: security policy, certificate check, user identity."""
    from asyncua import ua
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

    client.application_uri = APPLICATION_URI["twin"]
    client.name = client.description = "furnace-twin"
    client.session_timeout = SESSION_TIMEOUT_MS
    if security == "sign-encrypt":
        ident = ensure_identity(cert_dir, "twin")
        client.certificate_validator = TrustedPeers(cert_dir, "server")
        await client.set_security(SecurityPolicyBasic256Sha256, str(ident.cert), str(ident.key),
                                  mode=ua.MessageSecurityMode.SignAndEncrypt)
    elif security != "none":
        raise ValueError(f"unknown OPC UA security {security!r} (none or sign-encrypt)")
    if username:
        client.set_user(username)
        client.set_password(password or "")


class PasswordUsers(UserManager):
    """An asyncua user manager: only the given user names with their passwords get a session."""

    def __init__(self, users: Mapping[str, str]) -> None:
        self._users = dict(users)

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> Any:
        import secrets

        from asyncua.crypto.permission_rules import User, UserRole

        expected = self._users.get(username or "")
        if expected is None or password is None or not secrets.compare_digest(password.encode(), expected.encode()):
            log.warning("refused an OPC UA session for user %r", username)
            return None
        return User(role=UserRole.User, name=username)


async def secure_server(server: Any, *, security: str, cert_dir: str | Path, host: str, with_users: bool,
                        role: Role = "emulator") -> None:
    """Configure an ``asyncua.Server`` (after ``init``, before ``start``): policy, certificate, identity tokens.
    ``role``: the emulator's, or the twin's results server (``results-cert.der``)."""
    from asyncua import ua

    await server.set_application_uri(APPLICATION_URI[role])
    if security == "sign-encrypt":
        ident = ensure_identity(cert_dir, role, hosts=(host,))
        await server.load_certificate(str(ident.cert))
        await server.load_private_key(str(ident.key))
        server.set_security_policy([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt])
        server.set_certificate_validator(TrustedPeers(cert_dir, "client"))
    elif security == "none":
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
    else:
        raise ValueError(f"unknown OPC UA security {security!r} (none or sign-encrypt)")
    server.set_identity_tokens([ua.UserNameIdentityToken] if with_users else [ua.AnonymousIdentityToken])


class ReadOnlyUsers(UserManager):
    """An asyncua user manager for a server that only publishes (the twin's results): every session, anonymous
    too, is a plain user, who may read, browse and subscribe but write nothing the server marks read-only and
    add or delete no node (asyncua gives administrators every right)."""

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> Any:
        from asyncua.crypto.permission_rules import User, UserRole

        return User(role=UserRole.User, name=username)

