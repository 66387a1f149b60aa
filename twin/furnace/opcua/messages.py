"""What went wrong with a furnace over OPC UA, in one plain sentence for the user (the run's error, the 422 of
``POST /api/runs``, ``furnace-twin run`` and ``opcua-check``).

Certificates and security get the most care, because the stacks say least there.  A server that does not
trust this twin's certificate answers the secure channel with ``BadSecurityChecksFailed`` (OPC UA servers
should not say more; open62541 and node-opcua do so), with a ``BadCertificate...`` code, or just closes the
socket (asyncua then fails to decode: ``NotEnoughData``, ``AssertionError``).  With security on, any of these
is said as: the furnace refused this twin's certificate, *which file*, and where the twin keeps the
certificates it trusts itself.  When it is the twin that refused the furnace's certificate
(:class:`twin.furnace.opcua.security.TrustedPeers`), the refused certificate is saved under ``rejected/`` and
the sentence says where, and where to move it.

Example
-------
>>> from pathlib import Path
>>> text = certificate_refused("opc.tcp://plc:4840/", Path("data/opcua"), "BadSecurityChecksFailed")
>>> text.split(": add")[0]
"opc.tcp://plc:4840/ refused this twin's certificate data/opcua/twin-cert.der (BadSecurityChecksFailed)"
>>> text.endswith("(this twin trusts the furnace's certificate once it is in data/opcua/trusted)")
True
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from twin.furnace.opcua.browse import MissingNodes
from twin.furnace.opcua.security import trusted_dir

#: status codes with which a server refuses a client's certificate (OPC UA Part 4, 7.34)
CERTIFICATE_REFUSALS = (
    "BadSecurityChecksFailed", "BadCertificateInvalid", "BadCertificateUntrusted", "BadCertificateUriInvalid",
    "BadCertificateTimeInvalid", "BadCertificateIssuerTimeInvalid", "BadCertificateRevoked",
    "BadCertificateIssuerRevoked", "BadCertificateRevocationUnknown", "BadCertificateUseNotAllowed",
    "BadCertificateHostNameInvalid", "BadCertificatePolicyCheckFailed", "BadNoValidCertificates",
)
USER_REFUSALS = ("BadUserAccessDenied", "BadIdentityTokenRejected", "BadIdentityTokenInvalid")
POLICY_REFUSALS = ("BadSecurityPolicyRejected", "BadSecurityModeRejected")


class UntrustedServer(ConnectionError):
    """This twin refused the furnace's certificate (it is not in ``trusted/``); ``saved`` is where it was put."""

    def __init__(self, saved: Path | None, subject: str) -> None:
        super().__init__(f"untrusted server certificate {subject}")
        self.saved, self.subject = saved, subject


def certificate_refused(endpoint: str, cert_dir: Path, code: str) -> str:
    """The furnace's server did not accept this twin's certificate."""
    return (f"{endpoint} refused this twin's certificate {Path(cert_dir) / 'twin-cert.der'} ({code}): add it to "
            f"the trusted certificates of the furnace's OPC UA server (this twin trusts the furnace's certificate "
            f"once it is in {trusted_dir(cert_dir)})")


def explain(exc: BaseException, endpoint: str, options: Any, cert_dir: Path) -> str:
    """A user's sentence for a failed connection or request to the furnace at ``endpoint``."""
    from asyncua import ua
    from asyncua.common.utils import NotEnoughData

    name = type(exc).__name__
    secure = options.security != "none"
    if isinstance(exc, MissingNodes):
        return f"{endpoint}: {exc}"
    if isinstance(exc, UntrustedServer):
        where = f"saved as {exc.saved}" if exc.saved is not None else "not saved"
        return (f"this twin does not trust the certificate of {endpoint} ({exc.subject}, {where}): if it is the "
                f"furnace's, move it into {trusted_dir(cert_dir)}")
    if isinstance(exc, ConnectionRefusedError):
        return f"cannot reach {endpoint}: connection refused (is the furnace's OPC UA server running?)"
    if isinstance(exc, TimeoutError):
        return f"no answer from {endpoint} in time (each request may take {options.connect_timeout_s:g} s)"
    if isinstance(exc, OSError):
        return f"cannot reach {endpoint}: {exc.strerror or exc}"
    code = ua.status_codes.get_name_and_doc(exc.code)[0] if isinstance(exc, ua.UaStatusCodeError) else None
    if code in USER_REFUSALS:
        return (f"{endpoint} refused the user name or password (FURNACE_TWIN_OPCUA_USERNAME / _PASSWORD): {code}")
    if code in POLICY_REFUSALS or (isinstance(exc, ua.UaError) and "No matching endpoints" in str(exc)):
        return (f"{endpoint} does not offer security {options.security!r} (FURNACE_TWIN_OPCUA_SECURITY: none or "
                f"sign-encrypt, Basic256Sha256 Sign & Encrypt): {code or 'no such endpoint'}")
    if secure and (code in CERTIFICATE_REFUSALS or isinstance(exc, NotEnoughData | AssertionError)):
        return certificate_refused(endpoint, cert_dir, code or f"the server closed the secure channel: {name}")
    if code is not None:
        return f"{endpoint}: {code}: {exc}"
    return f"{endpoint}: {name}: {exc}"
