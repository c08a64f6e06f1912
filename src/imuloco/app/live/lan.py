"""A phone on the local network: this machine's addresses, a QR code of the phone's page, and
a self-signed certificate for the session (phones give motion sensors to HTTPS pages only).

Nothing here sends a packet: the addresses are the interfaces' own (psutil), the QR code is
drawn in the terminal (segno) and the certificate is made locally (cryptography); all three
are the ``[live]`` extra.
"""

from __future__ import annotations

import datetime
import ipaddress
import tempfile
from io import StringIO
from pathlib import Path

import psutil
import segno
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

CERT_DAYS = 30  # the session's certificate: long enough for a study day, short if copied


def lan_addresses() -> list[str]:
    """IPv4 addresses of this machine's network interfaces that other machines can reach:
    not loopback, not link-local (169.254.x.x); private ones (a home or lab network) first."""
    found = []
    for addrs in psutil.net_if_addrs().values():
        for a in addrs:
            try:
                ip = ipaddress.ip_address(a.address)
            except ValueError:  # a MAC address, or IPv6 with a zone
                continue
            if ip.version == 4 and not ip.is_loopback and not ip.is_link_local:
                found.append(ip)
    return [str(ip) for ip in sorted(set(found), key=lambda ip: (not ip.is_private, ip))]


def shown_host(host: str) -> str:
    """The host name to print in the addresses for a server listening on ``host``: the LAN
    address when it listens on every interface (``0.0.0.0``, ``::``; localhost when the
    machine has none), ``localhost`` for a loopback address, else ``host`` itself."""
    if host in ("0.0.0.0", "::", ""):
        return next(iter(lan_addresses()), "localhost")
    if host in ("127.0.0.1", "::1", "localhost"):
        return "localhost"
    return host


def qr_text(url: str) -> str:
    """``url`` as a QR code drawn with block characters, for a terminal (dark on light)."""
    out = StringIO()
    segno.make(url, error="l").terminal(out, compact=True, border=2)
    return out.getvalue()


def self_signed(hosts: list[str], folder: str | Path | None = None) -> tuple[Path, Path]:
    """A certificate for ``hosts`` (names or IP addresses) signed by its own key (ECDSA
    P-256, :data:`CERT_DAYS` days), written with its key as PEM into ``folder`` (default: a
    new temporary folder, readable by this user only). Returns (certificate, key) paths."""
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "imuloco live session")])
    alt = []
    for h in dict.fromkeys(hosts):
        try:
            alt.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            alt.append(x509.DNSName(h))
    now = datetime.datetime.now(datetime.UTC)
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=CERT_DAYS))
            .add_extension(x509.SubjectAlternativeName(alt), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .sign(key, hashes.SHA256()))
    folder = Path(tempfile.mkdtemp(prefix="imuloco-live-")) if folder is None else Path(folder)
    cert_path, key_path = folder / "cert.pem", folder / "key.pem"
    key_path.touch(mode=0o600)
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM,
                                           serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return cert_path, key_path


PHONE_WARNING = (
    "the certificate is this session's own, signed by no one: the phone warns once. Chrome: "
    "'Your connection is not private' -> Advanced -> Proceed; Safari: 'This Connection Is "
    "Not Private' -> Show Details -> visit this website. Then allow motion access.")
