"""Certificates for the zenoh mutual-TLS links: a small private CA and identities it signs.

A deployment has one CA (``ca.key``, ``ca.pem``) and one identity per zenoh participant
(``<name>.key``, ``<name>.pem``): the companion, each authorised threat source, each observer.
The identity's certificate common name (CN) is what zenoh's access control matches
(``access_control.subjects[].cert_common_names``), so it is the name the companion records as
the source of a threat. Keys are ECDSA P-256 (accepted by zenoh's rustls), in PKCS#8 PEM,
written with mode 0600; certificates are PEM. cryptography (the ``keys`` extra) is imported by
the functions that need it: without it they raise ``companion.extras.MissingExtra``.

Every certificate carries both the server and the client extended key usage (a zenoh peer may
listen or connect), and subject alternative names: the identity's name as a DNS name, plus the
host names and IP addresses given (``localhost`` and ``127.0.0.1`` for the companion by default),
which the other side checks when it connects to a ``tls/HOST:PORT`` endpoint.
"""

from __future__ import annotations

import datetime as _dt
import ipaddress
import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path

from companion.errors import ConfigError
from companion.extras import require

__all__ = [
    "Identity",
    "KeyMaterialError",
    "NAME_PATTERN",
    "check_name",
    "create_ca",
    "issue_identity",
    "load_certificate",
    "load_identity",
    "common_name",
    "verify_signed_by",
    "write_private_key",
    "write_certificate",
]

log = logging.getLogger(__name__)

#: Identity names: a zenoh key chunk and a DNS label (the source segment of threat keys).
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,62}$")
#: Names an identity may not take (``local`` is the source of unauthenticated threats).
RESERVED_NAMES = ("local", "ca")
DEFAULT_DAYS = 825


class KeyMaterialError(ConfigError):
    """A key or certificate cannot be created, read or verified (names the file or the name)."""


def check_name(name: str, what: str = "name") -> str:
    """Return ``name`` if it is a valid identity name, else raise ``KeyMaterialError`` naming ``what``."""
    if not isinstance(name, str) or not NAME_PATTERN.match(name):
        raise KeyMaterialError(
            f"{what}: must be 1-63 characters of A-Z a-z 0-9 _ - starting with a letter "
            f"or digit (it becomes a zenoh key chunk and a certificate CN), got {name!r}"
        )
    if name.lower() in RESERVED_NAMES:
        raise KeyMaterialError(f"{what}: {name!r} is reserved ({', '.join(RESERVED_NAMES)})")
    return name


@dataclass(frozen=True)
class Identity:
    """A private key and its certificate, in memory.

    Attributes
    ----------
    name : str
        The certificate's common name.
    key : cryptography private key
    cert : cryptography.x509.Certificate
    """

    name: str
    key: object
    cert: object


def _now() -> _dt.datetime:
    return _dt.datetime.now(_dt.UTC)


def _name(cn: str):
    require("keys", "cryptography")
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name(
        [x509.NameAttribute(NameOID.ORGANIZATION_NAME, "heli-companion"), x509.NameAttribute(NameOID.COMMON_NAME, cn)]
    )


def create_ca(name: str = "companion-ca", days: int = 3650) -> Identity:
    """A self-signed CA certificate and its key (ECDSA P-256)."""
    require("keys", "cryptography")
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec

    key = ec.generate_private_key(ec.SECP256R1())
    subject = _name(name)
    now = _now()
    cert = (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - _dt.timedelta(minutes=5))
        .not_valid_after(now + _dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    return Identity(name, key, cert)


def issue_identity(ca: Identity, name: str, *, hosts=(), days: int = DEFAULT_DAYS) -> Identity:
    """A key and a certificate with common name ``name`` signed by ``ca``.

    Parameters
    ----------
    ca : Identity
        The signing CA (``create_ca``).
    name : str
        Common name (``check_name``); also a DNS subject alternative name.
    hosts : sequence of str
        More subject alternative names: IP addresses or DNS names this identity is reached at.
    days : int
        Validity (days).
    """
    require("keys", "cryptography")
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID

    check_name(name)
    sans: list = [x509.DNSName(name)]
    for host in hosts:
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            if not re.match(r"^[A-Za-z0-9.-]{1,253}$", host):
                raise KeyMaterialError(f"host: expected an IP address or a DNS name, got {host!r}") from None
            sans.append(x509.DNSName(host))
    key = ec.generate_private_key(ec.SECP256R1())
    now = _now()
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(name))
        .issuer_name(ca.cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - _dt.timedelta(minutes=5))
        .not_valid_after(now + _dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=False,
                crl_sign=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(
            x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False
        )
        .add_extension(x509.SubjectAlternativeName(list(dict.fromkeys(sans))), critical=False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca.key.public_key()), critical=False)
        .sign(ca.key, hashes.SHA256())
    )
    return Identity(name, key, cert)


def write_private_key(identity: Identity, path: str | Path) -> Path:
    """Write the key as unencrypted PKCS#8 PEM, mode 0600 (created so: never readable by others)."""
    require("keys", "cryptography")
    from cryptography.hazmat.primitives import serialization

    path = Path(path)
    data = identity.key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )
    flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC
    fd = os.open(path, flags, 0o600)
    try:
        os.fchmod(fd, 0o600)  # an existing file keeps its mode through O_CREAT
        os.write(fd, data)
    finally:
        os.close(fd)
    return path


def write_certificate(identity: Identity, path: str | Path) -> Path:
    """Write the certificate as PEM (mode 0644)."""
    require("keys", "cryptography")
    from cryptography.hazmat.primitives import serialization

    path = Path(path)
    path.write_bytes(identity.cert.public_bytes(serialization.Encoding.PEM))
    path.chmod(0o644)
    return path


def load_identity(key_path: str | Path, cert_path: str | Path) -> Identity:
    """Read a PEM private key and its certificate (e.g. the CA, to issue one more identity)."""
    require("keys", "cryptography")
    from cryptography.hazmat.primitives import serialization

    key_path = Path(key_path)
    try:
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    except OSError as exc:
        raise KeyMaterialError(f"{key_path}: cannot read the private key: {exc.strerror or exc}") from None
    except (ValueError, TypeError) as exc:
        raise KeyMaterialError(f"{key_path}: not an unencrypted PEM private key ({exc})") from None
    cert = load_certificate(cert_path)
    return Identity(common_name(cert), key, cert)


def load_certificate(path: str | Path):
    """Read a PEM certificate; ``KeyMaterialError`` names the file when it is missing or not a certificate."""
    require("keys", "cryptography")
    from cryptography import x509

    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise KeyMaterialError(f"{path}: cannot read the certificate: {exc.strerror or exc}") from None
    try:
        return x509.load_pem_x509_certificate(data)
    except ValueError as exc:
        raise KeyMaterialError(f"{path}: not a PEM certificate ({exc})") from None


def common_name(cert) -> str:
    """The certificate's subject common name (``KeyMaterialError`` if it has none)."""
    require("keys", "cryptography")
    from cryptography.x509.oid import NameOID

    attrs = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    if not attrs:
        raise KeyMaterialError(f"certificate {cert.subject.rfc4514_string()!r} has no common name")
    return str(attrs[0].value)


def verify_signed_by(cert, ca_cert) -> None:
    """Raise ``KeyMaterialError`` unless ``cert`` was issued and signed by ``ca_cert`` and is valid now."""
    require("keys", "cryptography")
    from cryptography.exceptions import InvalidSignature

    if cert.issuer != ca_cert.subject:
        raise KeyMaterialError(
            f"certificate {common_name(cert)!r}: issued by {cert.issuer.rfc4514_string()}, "
            f"not by the CA {ca_cert.subject.rfc4514_string()}"
        )
    try:
        cert.verify_directly_issued_by(ca_cert)
    except (InvalidSignature, ValueError, TypeError) as exc:
        raise KeyMaterialError(
            f"certificate {common_name(cert)!r}: signature does not verify against the CA ({exc or type(exc).__name__})"
        ) from None
    now = _now()
    if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
        raise KeyMaterialError(
            f"certificate {common_name(cert)!r}: not valid now (valid "
            f"{cert.not_valid_before_utc:%Y-%m-%d} to {cert.not_valid_after_utc:%Y-%m-%d})"
        )
