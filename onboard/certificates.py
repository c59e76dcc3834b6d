"""The certificates of a robot's mutual TLS: one CA, the robot's server certificate, one client certificate per role.

``syt-onboard make-certs --out DIR`` writes, all PEM:

    ca.pem  ca.key               the authority (keep ca.key off the robot: it signs new certificates)
    robot.pem  robot.key         the agent's server certificate (SAN: localhost, 127.0.0.1, each --host)
    planner.pem  planner.key     a client certificate whose common name is its role, which the
    observer.pem  observer.key   robot's access-control list matches (``cert_common_names``)

Keys are ECDSA P-256 (rustls, Zenoh's TLS, accepts them) in PKCS#8, written mode 0600.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

ROLES = ("planner", "observer")  # client roles: the access-control list grants each its own keys
ROBOT = "robot"
DEFAULT_DAYS = 825
MAX_DAYS = 100 * 365  # a validity past the year 9999 cannot be written at all
_CLOCK_SKEW = dt.timedelta(hours=1)  # a robot whose clock lags a little still accepts a fresh certificate


@dataclass(frozen=True)
class Issued:
    """A private key and its certificate."""

    key: ec.EllipticCurvePrivateKey
    cert: x509.Certificate

    @property
    def common_name(self) -> str:
        return self.cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value

    def write(self, out: Path, stem: str) -> tuple[Path, Path]:
        """Write ``stem.pem`` (0644) and ``stem.key`` (0600) in ``out``."""
        cert_path, key_path = out / f"{stem}.pem", out / f"{stem}.key"
        cert_path.write_bytes(self.cert.public_bytes(serialization.Encoding.PEM))
        cert_path.chmod(0o644)
        key_pem = self.key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                         serialization.NoEncryption())
        fd = os.open(key_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(key_pem)
        key_path.chmod(0o600)  # the file may have existed with a looser mode
        return cert_path, key_path

    @classmethod
    def read(cls, out: Path, stem: str) -> Issued:
        key = serialization.load_pem_private_key((out / f"{stem}.key").read_bytes(), password=None)
        if not isinstance(key, ec.EllipticCurvePrivateKey):
            raise ValueError(f"{out / stem}.key: not an EC private key")
        return cls(key, x509.load_pem_x509_certificate((out / f"{stem}.pem").read_bytes()))


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "syt"),
                      x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _validity(days: int, not_before: dt.datetime | None) -> tuple[dt.datetime, dt.datetime]:
    start = not_before or dt.datetime.now(dt.timezone.utc) - _CLOCK_SKEW
    return start, start + dt.timedelta(days=days)


def make_ca(common_name: str = "syt CA", days: int = 10 * 365) -> Issued:
    """A self-signed authority that may sign end certificates only (path length 0)."""
    key = ec.generate_private_key(ec.SECP256R1())
    start, end = _validity(days, None)
    cert = (x509.CertificateBuilder()
            .subject_name(_name(common_name)).issuer_name(_name(common_name))
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(start).not_valid_after(end)
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                         content_commitment=False, key_encipherment=False,
                                         data_encipherment=False, key_agreement=False,
                                         encipher_only=False, decipher_only=False), critical=True)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
            .sign(key, hashes.SHA256()))
    return Issued(key, cert)


def _san(hosts: Iterable[str]) -> x509.SubjectAlternativeName:
    names: list[x509.GeneralName] = []
    for host in dict.fromkeys(hosts):  # unique, in order
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return x509.SubjectAlternativeName(names)


def issue(ca: Issued, common_name: str, *, server_hosts: Iterable[str] = (), days: int = DEFAULT_DAYS,
          not_before: dt.datetime | None = None) -> Issued:
    """An end certificate signed by ``ca``: a server's if ``server_hosts`` are given (its SAN), else a client's.

    ``not_before`` (with ``days``) sets the validity; a past window makes an expired certificate, for tests.
    """
    if days <= 0:
        raise ValueError(f"days must be positive, not {days}")
    hosts = list(server_hosts)
    key = ec.generate_private_key(ec.SECP256R1())
    start, end = _validity(days, not_before)
    usage = ExtendedKeyUsageOID.SERVER_AUTH if hosts else ExtendedKeyUsageOID.CLIENT_AUTH
    builder = (x509.CertificateBuilder()
               .subject_name(_name(common_name)).issuer_name(ca.cert.subject)
               .public_key(key.public_key()).serial_number(x509.random_serial_number())
               .not_valid_before(start).not_valid_after(end)
               .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
               .add_extension(x509.KeyUsage(digital_signature=True, key_encipherment=False, crl_sign=False,
                                            content_commitment=False, data_encipherment=False,
                                            key_agreement=False, key_cert_sign=False,
                                            encipher_only=False, decipher_only=False), critical=True)
               .add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
               .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca.key.public_key()),
                              critical=False))
    if hosts:
        builder = builder.add_extension(_san(hosts), critical=False)
    return Issued(key, builder.sign(ca.key, hashes.SHA256()))


def robot_hosts(extra: Iterable[str]) -> list[str]:
    """The names a planner may dial the robot by: loopback always, then the operator's."""
    hosts = ["localhost", "127.0.0.1", *extra]
    for host in hosts:
        if not host or any(c.isspace() or c in "/*,[]" for c in host):  # brackets: a DNS name no address matches
            raise ValueError(f"--host {host!r} is not a host name or IP address (an IPv6 one without brackets)")
    return hosts


def make_certificates(out: Path, hosts: Iterable[str] = (), days: int = DEFAULT_DAYS) -> dict[str, Issued]:
    """Write the CA, the robot's and each role's certificate and key in ``out``; return them by stem."""
    out.mkdir(parents=True, exist_ok=True)
    ca = make_ca(days=max(days, 10 * 365))
    issued = {"ca": ca, ROBOT: issue(ca, ROBOT, server_hosts=robot_hosts(hosts), days=days)}
    issued.update({role: issue(ca, role, days=days) for role in ROLES})
    for stem, item in issued.items():
        item.write(out, stem)
    return issued
